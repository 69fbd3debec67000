"""stochpend: ensembles of the stochastic pendulum with parametric white or Ornstein-Uhlenbeck noise.

Implements K. Mallick and P. Marcq, "On the stochastic pendulum with Ornstein-Uhlenbeck noise"
(2004): the ensemble simulator, the paper's analytic results, and its reduced dynamics.
"""

__version__ = "0.1.0"

from stochpend.simulate import simulate as simulate

__all__ = ["__version__", "simulate"]
