"""A test-only plugin that registers a first passage of the velocity (issue 23): loaded by name
(``--plugin tests.unit._passage_plugin``), in the command line's tests and on Dask workers."""

from stochpend.observables import FirstPassage, register

register(FirstPassage("Omega_up", lambda x, Omega, xi, t: Omega, threshold=1.0))
