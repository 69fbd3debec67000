"""Numbers and random streams, below everything that simulates: the kernels' math
(:mod:`.mathlib`, :mod:`.fastmath`), the counter-based random streams (:mod:`.rng`: a seed
becomes a Philox key here and nowhere else), Numba's compilation and its caches
(:mod:`._jitable`, :mod:`._jitcache`, :mod:`._cputarget`), the code digest that names a
simulated number's source (:mod:`._sources`) and the machine's measured rates
(:mod:`._calibration`). Imports nothing of the package but its version."""
