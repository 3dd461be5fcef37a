"""Test configuration: float64 and strict dtype promotion (silent float32 slips fail)."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")

# the bundled bench's calibration by `dtwin calibrate`, one per session (tests/_bench.py)
from _bench import bench_calibration  # noqa: E402,F401

# the spec calibrated on the independent records' baseline-1, one per session (tests/_independent.py)
from _independent import independent_calibrated_spec, independent_calibration  # noqa: E402,F401

import dtwin  # noqa: E402,F401  (the compilation cache; equinox's checks as NaN: dtwin._config)
from dtwin import _maps  # noqa: E402


def pytest_runtest_setup(item):
    """Before each test (no JAX trace running): drop JAX's caches if this worker nears the
    kernel's limit on memory mappings, which XLA's compiler does not survive (dtwin._maps)."""
    _maps.relieve()
