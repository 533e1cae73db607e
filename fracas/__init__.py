"""fracas: low-thrust mission analysis (TOM, TEAM, TSIM) on an Encke/Nystrom core.

Importing this package does not import JAX; the command line stays fast.  Numeric
modules call :func:`fracas._jax.configure` (float64, persistent compilation cache)
before they build any array.
"""

__version__ = "0.1.0"
