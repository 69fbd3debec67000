"""The engine: the step and its loops (:mod:`.integrator`), the host loop every run
goes through (:mod:`.runner`), and the backends' drivers (:mod:`.cpu` threads and SIMD lanes,
:mod:`.cuda`, the joint histogram :mod:`.joint`, the chunk layout :mod:`.layout`). Kernels are
specialised here per model, noise and precision; above it, nothing compiles."""
