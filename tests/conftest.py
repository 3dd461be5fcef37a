"""Test configuration: float64 and strict dtype promotion (silent float32 slips fail)."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")

import dtwin  # noqa: E402,F401  (configures the compilation cache)
