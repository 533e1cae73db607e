"""Test-wide JAX settings: float64 everywhere and strict dtype promotion, so that an
accidental float32 or an implicit int/float mix in the core fails loudly here."""

import jax

from fracas import _jax  # noqa: F401  (enables x64 and the compilation cache first)

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
