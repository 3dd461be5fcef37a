"""`make demo` produces its report from the bundled data (issue 4; quick form in CI), ends by
printing where its HTML report and figures are, and shows a progress line per step on stderr
(issue 51)."""

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
    # the paper's frequencies were reproduced in the report's first table (fm 500.294 vs
    # 500.1), ours in full (frequencies are never rounded to a tenth or four digits)
    assert "500.294 (500.1)" in report
    _check_ending(out, proc)


STEPS = ("frequencies", "modes", "stiffness", "paper cases", "sample records", "calibration",
         "identification", "discovery", "fleet")


def _check_ending(out: Path, proc: subprocess.CompletedProcess) -> None:
    """The last lines name the HTML report (which embeds every figure of the folder) and the
    figures; stderr has one progress line per step, in order, with the elapsed time."""
    lines = proc.stdout.strip().splitlines()
    assert lines[-3] == f"[demo] report: {out / 'report.html'}", lines[-3:]
    html = (out / "report.html").read_text()
    figures = sorted(p.name for p in out.glob("*.png"))
    assert lines[-2].startswith(f"[demo] figures ({len(figures)}) in {out}: "), lines[-2]
    assert lines[-2].endswith(", ".join(figures))
    assert html.count("data:image/png;base64,") == len(figures) >= 5
    for heading in ("Characteristic frequencies", "Natural frequencies", "Bundled records"):
        assert heading in html
    progress = [ln.split("]: ", 1)[1] for ln in proc.stderr.splitlines()
                if ln.startswith("demo [")]
    assert progress == ["starting", *STEPS, "HTML report"], proc.stderr[-2000:]
    assert "demo: done in" in proc.stderr


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
    for name in ("calibration_spectra.png", "calibration_gap.png", "identify_sun_fault.png",
                 "discover_gap.png", "discover_spectrum.png"):
        assert (out / name).stat().st_size > 1000, name
    # discovery and a fleet run on the bundled records (sections 8 and 9), nothing failed
    assert "Discovery on the sun-fault record" in report and "fleet run over" in report
    assert "FAILED" not in report
    import json

    assert "initial_gap" in json.loads((out / "discover.json").read_text())
    from dtwin.identify.fleet import load_results

    fleet = load_results(out / "fleet")
    assert sorted(Path(r["record"]).name for r in fleet) == [
        "bench_combined.dtwin.h5", "bench_healthy.dtwin.h5", "bench_sun_fault.dtwin.h5"]
    assert all(r["status"] == "ok" for r in fleet), fleet
    _check_ending(out, proc)
