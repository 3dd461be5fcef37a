"""The independent records (``../shared/independent``) and their calibration on baseline-1, as a
benchmark script that needs a calibrated spec makes it."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

IND = Path(__file__).resolve().parents[2] / "shared" / "independent"


def baseline_calibration(rows: list) -> Path:
    """The user's ``gearbox.toml`` calibrated on ``baseline-1.csv`` (written to a temporary
    folder); appends ``{"kind": "calibrate", "run_s": wall seconds}`` to `rows`."""
    from dtwin.identify.calibrate import calibrate

    w0 = time.perf_counter()
    res = calibrate([IND / "baseline-1.csv"], IND / "gearbox.toml")
    spec = Path(tempfile.mkdtemp()) / "calibrated.toml"
    res.write_spec(spec)
    rows.append(dict(kind="calibrate", run_s=time.perf_counter() - w0))
    return spec
