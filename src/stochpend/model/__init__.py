"""What is simulated and what is measured: the pieces a physicist names.

:mod:`.noises`, :mod:`.oscillators` and :mod:`.terms` (one file per noise, oscillator and
family term; public as ``stochpend.noises``, ``stochpend.oscillators``, ``stochpend.terms``),
the family they make (:mod:`.dynamics`), models and observables users write
(:mod:`.user_models`, public as ``stochpend.models``; :mod:`.observables`), plugins, the
parameters pieces declare (:mod:`.parameters`), a run's validated settings (:mod:`.settings`),
initial conditions (:mod:`.initial`), and the on-the-fly sums the statistics are built from
(:mod:`.power_sums`, :mod:`.passage`). Below the engine: nothing here compiles a loop."""
