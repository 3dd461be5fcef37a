"""The bundled bench's calibration, once per session: ``dtwin calibrate
data/samples/bench_healthy.dtwin.h5 --preset paper-bench --out …`` as the README runs it
(the command line's own :func:`dtwin.cli.main`, ~3 min). Under pytest-xdist the first worker
that needs it calibrates and the others read its folder (a file lock in the session's shared
temporary folder, as in ``tests/_independent.py``), so the run calibrates the bench once
whichever workers its tests land on."""

from __future__ import annotations

import contextlib
import io
import json
import os
from pathlib import Path

import pytest
from filelock import FileLock

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"


def run_cli(*args: str) -> tuple[int, dict | None, str]:
    """Exit code, the JSON object printed on stdout (None without one) and stderr of
    ``dtwin ARGS``."""
    from dtwin.cli import main

    out, err = io.StringIO(), io.StringIO()
    code = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([*args])
        except SystemExit as e:
            code = int(e.code or 0)
    text = out.getvalue()
    data = json.loads(text[text.find("{"):]) if "{" in text else None
    return code, data, err.getvalue()


@pytest.fixture(scope="session")
def bench_calibration(tmp_path_factory) -> Path:
    """The output folder of the bench's calibration (``calibrated.toml``, ``calibration.json``,
    ``manifest.json``)."""
    base = tmp_path_factory.getbasetemp()  # an xdist worker's lies in the session's folder
    shared = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "bench_cal"
    shared.mkdir(exist_ok=True)
    out = shared / "cal"
    with FileLock(str(shared / "lock")):
        if (out / "manifest.json").exists():  # another worker of this session calibrated
            return out
        code, _, err = run_cli("calibrate", str(SAMPLES / "bench_healthy.dtwin.h5"), "--preset",
                               "paper-bench", "--out", str(out))
        assert code == 0, err
        assert (out / "manifest.json").exists(), "calibrate wrote no manifest"
    return out
