"""A test-only plugin that registers a user observable and a per-path time average (issue 22,
item 3's proof): loaded by name (``--plugin tests.unit._observables_plugin``, or
``stochpend.plugins.load``), on Dask workers too; nothing in src/ names it."""

from stochpend.observables import Observable, TimeAverage, register

register(Observable("Omega2_plugin", lambda x, Omega, xi, t: Omega * Omega))
register(TimeAverage("Omega2_avg_plugin", lambda x, Omega, xi, t: Omega * Omega, window=(0.0, 4.0)))
