"""The bundled workflow as a user runs it (issue "Right on every machine", item 7): calibrate
on ``bench_healthy``, then ``discover`` on ``bench_sun_fault`` names the sun fault, and
``identify`` with the free list of the README finishes and exits 0. The commands are the
command line's own (:func:`dtwin.cli.main`, the same arguments a user types); the identify
run, cut to a few solver steps (``--max-steps``), which still reaches its uncertainty stage,
runs in ``make test-all``.

``bench_sun_fault`` was made with a sun tooth missing 60 % of its face (severity 0.6) by a translational twin
with 20 stiffness harmonics, a transmission error and planet position errors (not the fitted
twin, ``data/make_samples.py``). The linearised fit of discovery reads its severity past the
range (1.05); the search refits it inside the range in full simulation and keeps it.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from _bench import SAMPLES
from _bench import run_cli as _dtwin


@pytest.fixture(scope="module")
def calibrated(bench_calibration) -> Path:
    """The session's one calibration of the bench (tests/_bench.py: ``dtwin calibrate`` on
    bench_healthy with the paper-bench preset, as the README runs it)."""
    return bench_calibration / "calibrated.toml"


def test_discover_names_the_sun_fault_on_the_bundled_record(calibrated, tmp_path):
    """Measured on the samples made with the housing: held-out gap 25.04 → 2.81 dB,
    sun_local_fault (group sun_rotation) named alone, its severity refitted inside its range
    at 0.55 (truth 0.6). The two best scores of its first step are carrier-sideband
    look-alikes (the sun fault's comb lies on carrier orders); the sun fault is refit beside
    them as the best of another group (docs/discovery.md, "Two kinds of explanation per
    step")."""
    # one step (as the family benchmark's CI form, `--quick`): the claim is the effect named
    # first. A second step here refits a carrier-sideband look-alike and stops, none
    # significant (measured: the same sun_local_fault step, then "no candidate significant
    # and identified", ring_local_fault at p = 0.99), ~20 % of the command's time; stopping
    # when nothing more is significant is checked in `make test` by the null and healthy
    # records (tests/test_discover_workflow.py, tests/test_discover_independent.py), the full
    # three-step search by `make test-all` (test_discover_names_the_sun_fault_alone_on_the_
    # bundled_record below). If discovery stops naming the sun fault first, or its refit
    # inside the range, this form fails as the full one does: step 1 is the same step.
    res = _discover_bench(calibrated, tmp_path, "--max-steps", "1")
    steps = res["steps"]
    assert len(steps) == 1 and steps[0]["group"] == "sun_rotation", [s["named"] for s in steps]
    _check_sun_fault_named(res)


@pytest.mark.slow
def test_discover_names_the_sun_fault_alone_on_the_bundled_record(calibrated, tmp_path):
    """The README's discover as it is (three steps at most): the sun fault is named first and
    nothing else is added."""
    res = _discover_bench(calibrated, tmp_path)
    steps = res["steps"]
    assert steps and steps[0]["group"] == "sun_rotation", [s["named"] for s in steps]
    assert all(s["group"] == "sun_rotation" for s in steps)
    _check_sun_fault_named(res)


def _discover_bench(calibrated, tmp_path, *extra) -> dict:
    """`dtwin discover` on bench_sun_fault with the calibrated spec, as the README runs it
    (``--no-depth``: its depth is severity's, tests/test_one_fault_depth.py): its JSON."""
    code, res, err = _dtwin("discover", str(SAMPLES / "bench_sun_fault.dtwin.h5"), "--spec",
                            str(calibrated), "--no-depth", *extra, "--out",
                            str(tmp_path / "diag"), "--json")
    assert code == 0, err
    return res


def _check_sun_fault_named(res: dict) -> None:
    """The gap halves, the sun fault's severity lies in its range, refitted inside it."""
    steps = res["steps"]
    assert res["final_gap"]["total"] < 0.5 * res["initial_gap"]["total"]
    main = steps[0]["main"]
    assert 0.0 < main["value"] <= 1.0
    # the linearised fit put the kept candidate past its range: it was refitted inside it in
    # full simulation and says so; another candidate past its range says why, in its row
    chosen = next(c for c in steps[0]["candidates"] if c["name"] == steps[0]["effect"])
    assert chosen["out_of_range"] and "refitted inside the range" in chosen["out_of_range"]
    for s in steps:
        for c in s["candidates"]:
            assert c["out_of_range"] is None or "outside its physical range" in c["out_of_range"]


def _identify_readme_free_list(calibrated, out: Path):
    """``dtwin identify`` with the README's free list, cut to 3 solver steps: its exit code,
    JSON result and stderr."""
    return _dtwin("identify", str(SAMPLES / "bench_sun_fault.dtwin.h5"), "--spec",
                  str(calibrated), "--free", "k_sun_planet,zeta_mesh,sun_fault",
                  "--max-steps", "3", "--out", str(out), "--json")


FREE = {"k_sun_planet", "zeta_mesh", "sun_fault"}


@pytest.mark.slow
def test_identify_with_the_readme_free_list_finishes(calibrated, tmp_path):
    """`dtwin identify REC --spec CAL --free k_sun_planet,zeta_mesh,sun_fault` exits 0 (it
    crashed in its uncertainty stage after 17 min: the loss compared with the parameter
    vector); cut to 3 solver steps. Every stage ran: the fit of both excitation/response
    splits, their intervals (where it crashed) and the check against the calibration.

    In ``make test-all`` only (6–12 min on 2 cores, compilation mostly, even on a 1 s window):
    ``make test`` reaches the branch that crashed in a second
    (tests/test_reliability_uncertainty.py), and identify through the splits of a calibrated
    spec and its check against the calibration in tests/test_split.py and
    ``test_calibrated_bench_flags_stiffness_confounded_with_the_calibration`` below."""
    out = tmp_path / "ident"
    code, res, err = _identify_readme_free_list(calibrated, out)
    assert code == 0, err
    assert res is not None, "identify --json printed no result"
    assert set(res["values"]) == FREE, res.keys()
    assert set(res["intervals_95"]) == FREE
    assert (out / "manifest.json").exists()


# ------------------------------------------------ the calibration's load shares (issue 19)
def test_calibration_fits_unequal_load_sharing_on_the_bench(bench_calibration):
    """The bundled bench_healthy record (made by a translational twin with 20 stiffness
    harmonics, a transmission error and pin-hole position errors of 0.1 and −0.075 mrad, 5 and
    4 µm, that load the planets unequally: not the calibrating twin) holds carrier orders
    k f_c over the floor. Without load shares the calibration left it at 24 dB held out
    (the frequency response bent to hide the low band); with them the held-out gap falls below
    a third of the uncalibrated one and the low band to within 3 dB. The calibrated spec
    carries the shares, and a twin built from it has the clearances that give them."""
    import json

    import numpy as np

    from dtwin.model.parts.imperfections import MeshOffsets
    from dtwin.spec import load_spec
    from dtwin.spec.build import build_twin

    res = json.loads((bench_calibration / "calibration.json").read_text())
    names = [p["name"] for p in res["parameters"]]
    assert "load_share_1" in names and "load_share_2" in names
    before = res["gap_before"]["total"]
    print(before, res["gap_heldout"]["total"], res["gap_confirmed"])
    assert res["gap_heldout"]["total"] < before / 3
    assert res["gap_confirmed"]["total"] < before / 3
    assert res["gap_confirmed"]["bands"]["low"] < 3.0
    spec = load_spec(bench_calibration / "calibrated.toml")
    shares = spec["imperfections"]["load_sharing"]
    assert shares[0] == 1.0 and max(abs(v - 1.0) for v in shares) > 0.1
    (part,) = [p for p in build_twin(spec, kind="torsional").parts if isinstance(p, MeshOffsets)]
    assert np.ptp(np.asarray(part.e_sp)) > 0


@pytest.fixture(scope="module")
def bench_severities(calibrated):
    """``estimate_severity`` of the sun fault with the calibrated spec, as ``dtwin severity``
    runs it (the sideband ratio, dtwin.identify.line_ratio), on bench_sun_fault (truth 0.6)
    and bench_healthy (truth 0)."""
    from dtwin import read_record
    from dtwin.identify.severity import estimate_severity
    from dtwin.spec import load_spec
    from dtwin.spec.build import twin_kind

    assert twin_kind(load_spec(calibrated)) == "translational"
    sev = estimate_severity(read_record(SAMPLES / "bench_sun_fault.dtwin.h5"), calibrated, "sun")
    healthy = estimate_severity(read_record(SAMPLES / "bench_healthy.dtwin.h5"), calibrated,
                                "sun")
    print(sev.summary(), healthy.summary(), sep="\n")
    return sev, healthy


def test_calibrated_bench_severity_reads_the_fault(bench_severities):
    """Issue 19's bench acceptance, severity part, and the first target of "One fault depth":
    with the calibrated spec (the twin it was calibrated with, translational as paper-bench
    says), read from the sideband ratio, the sun fault (truth 0.6) reads within 25 % of the
    truth with an interval well clear of 0; the healthy record reads at most 0.02 with an
    interval that holds 0 (no fault line over the noise). Measured with the spectrum fit (the
    default before the ratio) on the samples made with the housing (pin-hole errors 0.1 and
    −0.075 mrad): 0.595 [0.560, 0.630] (0.522 [0.492, 0.552] with a calibration linearised
    once)."""
    sev, healthy = bench_severities
    assert sev.method.startswith("line ratio")
    assert abs(sev.severity - 0.6) <= 0.25 * 0.6 and sev.interval[0] > 0.2
    assert healthy.severity <= 0.02
    assert healthy.interval[0] == 0.0 and "over the noise" in healthy.status


def test_calibrated_bench_severity_interval_holds_the_truth(bench_severities):
    """The sun fault's 95 % interval holds the truth 0.6 (issue "One fault depth", item 5).
    With a calibration linearised once (its full twin 0.9 dB off the fitted response) it read
    0.522 [0.492, 0.552]: a fit that passed its own checks and missed the truth. Linearised
    until the full twin and the fitted response agree (`CalibrationSettings.converge_db`), the
    calibration confirms at 0.41 dB instead of 1.26 dB, and the fault reads 0.595 [0.560,
    0.630]."""
    sev, _ = bench_severities
    assert sev.interval[0] <= 0.6 <= sev.interval[1]


def test_calibrated_bench_flags_stiffness_confounded_with_the_calibration(calibrated):
    """Issue 19's bench acceptance, identify part (reduced: at the spec's values, no solver
    steps; the full fit is tests/test_severity_independent.py's slow bench tests): with the
    calibration held, the 5 kHz record gives k_sun_planet a ±10 % interval; with the
    excitation's four harmonics and the two load-share clearances free as well it cannot tell
    the stiffness from them, and the check flags it, while the sun fault's sidebands keep it
    determined."""
    import jax.numpy as jnp
    import numpy as np

    from dtwin import read_record
    from dtwin.identify.confounding import calibrated_excitation, calibration_confounding
    from dtwin.identify.problem import make_problem
    from dtwin.identify.residuals import point_groups
    from dtwin.identify.solve import value_and_jacfwd
    from dtwin.identify.uncertainty import analyse, expected_noise_rss
    from dtwin.spec import load_spec

    spec = load_spec(calibrated)
    assert calibrated_excitation(spec) == tuple(
        f"excitation_ring_{cs}_{h}" for cs in ("cos", "sin") for h in range(1, 5))
    problem, _ = make_problem(read_record(SAMPLES / "bench_sun_fault.dtwin.h5"), calibrated,
                              ["k_sun_planet", "sun_fault"], initial={"sun_fault": 0.5})
    groups, rss = point_groups(problem.observations), expected_noise_rss(problem.observations)
    r, J = value_and_jacfwd(jnp.zeros(2), problem)
    held = analyse(problem.pset, np.zeros(2), np.asarray(r), np.asarray(J), groups,
                   n_profiled_gains=problem.n_profiled_gains, expected_rss=rss)
    assert held.not_determined == {}
    free, wide = calibration_confounding(problem, np.zeros(2), held, spec, groups=groups,
                                         expected_rss=rss, jacobian=value_and_jacfwd)
    print(free.not_determined, wide)
    assert list(free.not_determined) == ["k_sun_planet"]
    assert free.not_determined["k_sun_planet"].startswith(
        "confounded with the calibration (4 transmission-error harmonics and 2 load-share "
        "clearances")
    lo, hi = wide["k_sun_planet"]
    assert hi / lo > 3.0
