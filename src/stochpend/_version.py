"""The package's version, in a module of its own: the package's modules import it from here, not
from ``stochpend`` (whose public names import them lazily), so that no import cycle passes
through the package itself."""

__version__ = "0.1.0"
