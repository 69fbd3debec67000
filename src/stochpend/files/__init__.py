"""Results files: NetCDF in and out with checksums and provenance (:mod:`.io`, public as
``stochpend.io``), writes that never leave a half-written file (:mod:`._files`), the plain
reader of ``show`` (:mod:`._plain`), TOML configuration files (:mod:`._toml`)."""
