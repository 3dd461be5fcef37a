"""The independent records (``../shared/independent/``: a gearbox dtwin did not simulate) and
one calibrated spec for the whole session, calibrated on baseline-1 alone
(:func:`dtwin.identify.calibrate.calibrate`, ~1.5–2 min). Tests that use it share the xdist group
``independent`` so that one worker calibrates once."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

IND = Path(__file__).resolve().parents[2] / "shared" / "independent"
needs_independent = pytest.mark.skipif(not (IND / "baseline-1.csv").exists(),
                                       reason="../shared/independent/ is not beside the checkout")


@pytest.fixture(scope="session")
def independent_calibrated_spec(independent_calibration) -> Path:
    """Path of the spec calibrated on ``baseline-1.csv``."""
    return independent_calibration[1]


@pytest.fixture(scope="session")
def independent_calibration(tmp_path_factory):
    """``(CalibrationResult, path of the calibrated spec)`` of the calibration on
    ``baseline-1.csv`` (the user's ``gearbox.toml`` is checked unmodified)."""
    from dtwin.identify.calibrate import calibrate

    if not (IND / "baseline-1.csv").exists():
        pytest.skip("../shared/independent/ is not beside the checkout")
    spec_file = IND / "gearbox.toml"
    before = hashlib.sha256(spec_file.read_bytes()).hexdigest()
    res = calibrate([IND / "baseline-1.csv"], spec_file)
    assert hashlib.sha256(spec_file.read_bytes()).hexdigest() == before
    path = tmp_path_factory.mktemp("independent_cal") / "calibrated.toml"
    res.write_spec(path)
    return res, path
