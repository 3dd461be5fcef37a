"""`make demo` produces its report from the bundled data (issue 4; quick form in CI)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest


def _run_demo(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dtwin.identify.demo", "--out", str(out), *extra],
                          capture_output=True, text=True, timeout=1500)


def test_demo_quick_writes_report_figures_and_manifest(tmp_path):
    out = tmp_path / "demo"
    proc = _run_demo(out, "--quick")
    assert proc.returncode == 0, proc.stderr[-3000:]
    # the library's warnings (the bench preset's profile shift) as one line each, as in the CLI,
    # not Python's default "file:line: UserWarning" with the source line
    assert "UserWarning" not in proc.stderr and "spec.py:" not in proc.stderr, proc.stderr[-2000:]
    report = (out / "report.md").read_text()
    for heading in ("Characteristic frequencies", "Natural frequencies", "Mesh stiffness",
                    "three cases", "Bundled records"):
        assert heading in report
    assert "FAILED" not in report
    for name in ("modes_paper-sim.png", "stiffness_paper-sim.png", "sim_healthy_spectrum.png",
                 "bench_sun_fault_spectrum.png", "manifest.json"):
        assert (out / name).stat().st_size > 1000, name
    # the bundled records are inputs of the run: hashed in the manifest
    import json

    manifest = json.loads((out / "manifest.json").read_text())
    assert any("bench_healthy" in k for k in manifest["inputs"])
    # the paper's frequencies were reproduced in the report's first table (fm 500.3 vs 500.1)
    assert "500.3 (500.1)" in report


@pytest.mark.slow
def test_demo_full(tmp_path):
    from dtwin.spec import load_spec

    out = tmp_path / "demo"
    proc = _run_demo(out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = (out / "report.md").read_text()
    # the README's main workflow: calibrate on the healthy record, then identify
    assert "Calibration on the healthy bundled record" in report
    cal = load_spec(out / "calibrated.toml")  # a spec every command accepts
    assert cal["gears"]["z_ring"] == 84 and cal["calibration"]
    for name in ("calibration_spectra.png", "calibration_gap.png", "identify_sun_fault.png"):
        assert (out / name).stat().st_size > 1000, name
