"""The independent records (``../shared/independent/``: a gearbox dtwin did not simulate) and
one calibrated spec for the whole session, calibrated on baseline-1 alone
(:func:`dtwin.identify.calibrate.calibrate`, ~1.5–2 min). Under pytest-xdist the first worker
that needs it calibrates and the others read its result (a file lock in the session's shared
temporary folder), so the run calibrates once whichever workers the tests land on."""

from __future__ import annotations

import hashlib
import os
import pickle
from pathlib import Path

import pytest
from filelock import FileLock

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
    base = tmp_path_factory.getbasetemp()  # an xdist worker's lies in the session's folder
    shared = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "independent_cal"
    shared.mkdir(exist_ok=True)
    result, path = shared / "result.pickle", shared / "calibrated.toml"
    with FileLock(str(shared / "lock")):
        if result.exists():  # another worker of this session calibrated
            return pickle.loads(result.read_bytes()), path
        spec_file = IND / "gearbox.toml"
        before = hashlib.sha256(spec_file.read_bytes()).hexdigest()
        res = calibrate([IND / "baseline-1.csv"], spec_file)
        assert hashlib.sha256(spec_file.read_bytes()).hexdigest() == before
        res.write_spec(path)
        part = result.with_suffix(".part")
        part.write_bytes(pickle.dumps(res))
        part.replace(result)  # whole or absent, should this worker die
    return res, path
