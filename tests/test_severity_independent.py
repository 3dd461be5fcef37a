"""Severity in physical terms (peak mesh-stiffness loss) and honest intervals (lack-of-fit
widening), on records dtwin did not make: ../shared/independent/ (an independent simulator of
the paper's gearbox; its sun-fault series states the peak stiffness loss, truth.json), after
calibrating on baseline-1 alone; and the rule's pieces against Monte Carlo."""

from __future__ import annotations

import json
import types
from pathlib import Path

import numpy as np
import pytest

IND = Path(__file__).resolve().parents[2] / "shared" / "independent"
needs_independent = pytest.mark.skipif(not (IND / "baseline-1.csv").exists(),
                                       reason="../shared/independent/ is not beside the checkout")
SERIES = ("sun-fault-0.15", "sun-fault-0.30", "sun-fault-0.60", "sun-fault-0.90")


def _truth(name: str) -> float:
    t = json.loads((IND / "truth.json").read_text())
    return float(t["records"][name]["effects"][0]["peak_stiffness_loss"])


# ---------------------------------------------------------------- the lack-of-fit rule's pieces
def test_noise_mse_matches_monte_carlo():
    """The mean square log residual the noise alone leaves, by quadrature, against simulated
    complex Gaussian noise of median amplitude F around lines of several S/F."""
    from dtwin.identify.uncertainty import _rice_log_mse

    rng = np.random.default_rng(0)
    sigma = 1.0 / np.sqrt(2.0 * np.log(2.0))
    for snr in (0.0, 0.5, 1.0, 3.0, 10.0, 100.0):
        n = sigma * (rng.standard_normal(200_000) + 1j * rng.standard_normal(200_000))
        mc = np.mean((np.log(np.sqrt(snr ** 2 + 1) + 1) - np.log(np.abs(snr + n) + 1)) ** 2)
        assert float(_rice_log_mse(np.array(snr))) == pytest.approx(mc, rel=0.02)


def test_expected_noise_rss_is_the_loss_of_a_right_model():
    """A spectrum of lines in noise, compared with the right model (the residual of
    dtwin.identify.residuals): its loss over the expected loss is 1 within the Monte Carlo
    scatter, and an amplitude error of 50 % on the lines raises it well above the limit."""
    from dtwin.identify.uncertainty import LACK_OF_FIT_LIMIT, expected_noise_rss

    rng = np.random.default_rng(1)
    m = 4000
    floor = np.full(m, 2.0)
    sigma = floor / np.sqrt(2.0 * np.log(2.0))
    lines = np.where(np.arange(m) % 2 == 0, 10 ** rng.uniform(0, 2, m), 0.0) * floor
    meas = np.abs(lines + sigma * (rng.standard_normal(m) + 1j * rng.standard_normal(m)))
    obs = types.SimpleNamespace(floor=floor, meas=np.log(meas + floor), weight=1.0,
                                env_weight=0.0)

    def loss(model):
        return np.sum((np.log(np.sqrt(model ** 2 + floor ** 2) + floor) - obs.meas) ** 2)

    e = expected_noise_rss([obs])
    assert loss(lines) / e == pytest.approx(1.0, abs=0.1)
    assert loss(1.5 * lines) / e > LACK_OF_FIT_LIMIT


# ---------------------------------------------------------------- the independent records
@pytest.fixture(scope="module")
def calibrated_spec(independent_calibrated_spec):
    """The independent gearbox calibrated on baseline-1 alone (the session's one calibration,
    tests/_independent.py)."""
    return independent_calibrated_spec


def _estimate(name: str, spec, ramps, jackknife=False):
    """The severity's defaults, as `dtwin severity REC --spec cal/calibrated.toml` runs it
    after `dtwin calibrate` on the user's spec (torsional, gearbox.toml): the translational
    twin (dtwin.spec.build.SEVERITY_KIND: a sun tooth fault loads one mesh at a time, and the sun
    floats on its bearing under it; the torsional twin, whose sun cannot, makes the same loss
    4–10× louder — measured: sun-fault-0.60, 3.9 % [2.7, 6.9] with the torsional twin the spec
    was calibrated with, truth 36 %) and the low band (the fault's strongest lines, the comb
    k f_sf ± f_s, 30–45 dB over the floor on these records; the mesh bands hold only weak
    sidebands)."""
    from dtwin import read_record
    from dtwin.identify.severity import estimate_severity

    est = estimate_severity(read_record(IND / f"{name}.csv"), spec, "sun", ramps=ramps,
                            initial_severity=0.2, jackknife=jackknife, method="spectrum")
    assert est.fit.problem.twin.kind == "translational" and "calibrated with" in est.note
    assert est.fit.problem.observations[0].freqs[0] < 0.9 * 3 * 30 * 21 / 102  # the low band
    assert est.low_band and est.to_dict()["low_band"] is True
    return est


def _assert_honest_table(est):
    """A fit whose loss stands above the noise never prints 'ok' for the severity."""
    tab = est.fit.table()
    if est.widened > 1.0:
        assert "widened" in est.status and "widened" in tab
        row = [r for r in tab.splitlines() if r.startswith("sun_fault")][0]
        assert not row.rstrip().endswith("ok")


@needs_independent
def test_sun_fault_peak_loss_on_independent_record(calibrated_spec):
    """CI form: sun-fault-0.60 (truth: peak stiffness loss 36 %) within 25 % with the
    translational twin, the fault's default (sharp) loss and the low band; the peak relative
    to the mean mesh stiffness. Both ends of the calibration's excitation/response split are
    fitted (dtwin.identify.split.stiffness_split); the calibrated one fits this record best
    and is reported, and the interval, the union over the splits the record cannot reject,
    holds the truth. Measured: 28.8 % with the calibrated split (loss 156.5), 53.3 % with the
    stiffness waveform's excitation and a flat response (175.1, within what the best fit
    leaves unexplained at a lack of fit of 1.27): 95 % [21.6, 80.0] %, NOT DETERMINED."""
    from dtwin.identify.split import SPLIT_CALIBRATED, SPLIT_STIFFNESS

    truth = _truth("sun-fault-0.60")
    est = _estimate("sun-fault-0.60", calibrated_spec, None)
    print(est.summary())
    print(est.shapes_table())
    _assert_honest_table(est)
    assert abs(est.peak_loss - truth) <= 0.25 * truth
    rows = {r["excitation"]: r for r in est.shapes}
    assert set(rows) == {SPLIT_CALIBRATED, SPLIT_STIFFNESS}
    assert est.excitation == SPLIT_CALIBRATED
    assert rows[SPLIT_CALIBRATED]["loss"] < rows[SPLIT_STIFFNESS]["loss"]
    assert est.peak_interval[0] <= truth <= est.peak_interval[1]


@pytest.fixture(scope="module")
def series(calibrated_spec):
    """The four sun-fault records, translational twin, low band, the loss's shape profiled
    (sharp and soft edges) and the band jackknife."""
    ests = [_estimate(n, calibrated_spec, (0.05, 0.3), jackknife=True) for n in SERIES]
    for n, e in zip(SERIES, ests, strict=True):
        print(n, _truth(n), e.summary())
    return ests


@needs_independent
@pytest.mark.slow
def test_sun_fault_series_in_order(series):
    """Full form: the four sun-fault records (peak loss 9, 18, 36, 54 %) come out in order, and
    no interval is called ok while the loss stands well above the noise."""
    for e in series:
        _assert_honest_table(e)
    peaks = [e.peak_loss for e in series]
    assert all(a < b for a, b in zip(peaks, peaks[1:], strict=False))


@needs_independent
@pytest.mark.slow
def test_sun_fault_series_peak_loss_and_coverage(series):
    """The issue's targets: within 25 % (36, 54 %) or 0.05 absolute (9, 18 %), 95 % intervals
    holding the truth ≥ 3 of 4. Measured (low band, ramps 0.05/0.3, band jackknife): 9.8 %
    [2.8, 35.3] (NOT DETERMINED), 17.5 % [10.2, 35.1] (widened), 28.8 % [6.2, 84.6] (NOT
    DETERMINED), 53.1 % [0.4, 99.4] (NOT DETERMINED) for 9/18/36/54 %: all four within
    tolerance, 4 of 4 covered; the bands disagree, and the jackknife says so."""
    truths = [_truth(n) for n in SERIES]
    for e, t in zip(series, truths, strict=True):
        assert abs(e.peak_loss - t) <= (0.25 * t if t > 0.3 else 0.05)
    covered = sum(e.peak_interval[0] <= t <= e.peak_interval[1]
                  for e, t in zip(series, truths, strict=True))
    assert covered >= 3


# ---------------------------------------------------------------- the bundled bench records
SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"


@pytest.fixture(scope="module")
def bench_spec(tmp_path_factory):
    """paper-bench calibrated on bench_healthy (records made by a translational twin with 20
    stiffness harmonics, transmission error and planet position errors: not the fitted twin)."""
    from dtwin.identify.calibrate import calibrate
    from dtwin.spec import preset

    res = calibrate([SAMPLES / "bench_healthy.dtwin.h5"], preset("paper-bench"))
    path = tmp_path_factory.mktemp("bench") / "calibrated.toml"
    res.write_spec(path)
    return path


def _overlap(a, b) -> bool:
    return a[0] <= b[1] and b[0] <= a[1]


def _bench_identify(bench_spec):
    from dtwin import read_record
    from dtwin.identify.fit import fit

    rec = read_record(SAMPLES / "bench_sun_fault.dtwin.h5")
    # 33–41 Levenberg–Marquardt steps to converge (zeta_mesh wanders along its flat direction)
    ident = fit(rec, bench_spec, ["k_sun_planet", "zeta_mesh", "sun_fault"],
                initial={"sun_fault": 0.3}, max_steps=80)
    print(ident.table())
    return ident


@pytest.mark.slow
def test_bench_identify_severity_and_fleet_agree(bench_spec, tmp_path):
    """identify (k_sun_planet, zeta_mesh, sun_fault), severity and fleet on bench_sun_fault,
    each with the twin the spec was calibrated with (translational, dtwin.spec.build.twin_kind),
    agree within their intervals; bench_healthy's severity interval holds 0; mesh damping,
    which this 5 kHz record cannot determine, is flagged (README).
    Measured: identify fits both ends of the calibration's excitation/response split
    (dtwin.identify.split): calibrated k_sun_planet 2.81e8, sun_fault 0.542 (loss 70.98, 141.6
    with the low band), stiffness waveform with a flat response 2.58e9, 0.641 (loss 68.37, 161.3
    with the low band: rejected); reported sun_fault 0.542 [0.496, 0.587] (33 steps), zeta_mesh
    NOT DETERMINED, lack of fit 1.17; severity 0.490 [0.406, 0.518] (excitation splits); fleet
    [0.480, 0.557]; bench_healthy 0.002 [0, 0.031]."""
    from dtwin import read_record
    from dtwin.identify.fleet import FleetSettings, run_fleet
    from dtwin.identify.severity import estimate_severity

    ident = _bench_identify(bench_spec)
    assert ident.converged
    assert ident.status("zeta_mesh") == "NOT DETERMINED"
    sev = estimate_severity(read_record(SAMPLES / "bench_sun_fault.dtwin.h5"), bench_spec, "sun")
    print(sev.summary())
    run_fleet([str(SAMPLES / "bench_sun_fault.dtwin.h5")], bench_spec, tmp_path / "fleet",
              FleetSettings(free=("sun_fault",)), engine="local", progress=False)
    entries = [json.loads(p.read_text()) for p in (tmp_path / "fleet").rglob("*.json")]
    (entry,) = [e for e in entries if isinstance(e, dict) and e.get("kind") == "fit"]
    fleet_iv = tuple(entry["intervals_95"]["sun_fault"])
    ivs = [ident.interval("sun_fault"), sev.interval, fleet_iv]
    print(ivs)
    assert all(_overlap(a, b) for a in ivs for b in ivs)
    healthy = estimate_severity(read_record(SAMPLES / "bench_healthy.dtwin.h5"), bench_spec, "sun")
    print(healthy.summary())
    assert healthy.interval[0] <= 1e-3


@pytest.mark.slow
def test_bench_identify_flags_mesh_stiffness(bench_spec):
    """A 5 kHz record cannot determine k_sun_planet (README): identify flags it, or its
    interval holds the truth's value (the ISO stiffness of paper-bench).
    Measured: with the calibration held the fit reads 2.88e8 [2.14e8, 3.86e8] N/m (the
    stiffness times the transmission error and share clearances calibration fitted at the
    ISO value); dtwin.identify.confounding frees the excitation's four harmonics and the two
    clearances at the optimum and the interval becomes [1.06e8, 7.80e8]: flagged, with the
    reason given. The other end of the calibration's excitation/response split reads 2.58e9
    with a lower loss on the mesh bands; the low band, which neither fit uses, rejects it
    (161.3 against 141.6). The sun fault stays determined."""
    from dtwin.spec import load_spec, lumped_from_spec

    ident = _bench_identify(bench_spec)
    lp = lumped_from_spec(load_spec(bench_spec))
    lo, hi = ident.interval("k_sun_planet")
    assert ident.status("k_sun_planet") == "NOT DETERMINED" or lo <= float(lp.k_sun_planet) <= hi
    assert ident.status("sun_fault") != "NOT DETERMINED"


@pytest.mark.slow
def test_bench_identify_from_the_default_start_flags_mesh_stiffness(bench_spec):
    """The same from the default start (sun_fault 0.001, k_sun_planet at the ISO value), as
    `dtwin identify bench_sun_fault --free k_sun_planet,sun_fault` runs it: the first optimum
    (sun_fault ≈ 0) is left by the severity's profile, the second (k_sun_planet 7.09e8, a
    minimum where the fault's sidebands near 2 f_m follow the stiffness) by the stiffness's
    scan, and the fit ends where the calibration confounds the stiffness: flagged. The fault
    severity is fitted with both ends of the calibration's excitation/response split too
    (dtwin.identify.split), and the union of their intervals would hold both readings.
    Measured: calibrated split loss 122.3 → 74.2 (profile) → 71.0 (scan), k_sun_planet 2.89e8
    (with the calibration free [1.22e8, 6.82e8]), sun_fault 0.544 [0.498, 0.589]: reported, its
    loss with the low band 141.6; the stiffness waveform with a flat response loss 68.5,
    k_sun_planet 1.92e9, sun_fault 0.605, with the low band 156.9: rejected."""
    from dtwin import read_record
    from dtwin.identify.fit import fit
    from dtwin.identify.split import SPLIT_CALIBRATED

    rec = read_record(SAMPLES / "bench_sun_fault.dtwin.h5")
    ident = fit(rec, bench_spec, ["k_sun_planet", "sun_fault"], max_steps=80)
    print(ident.table())
    assert [m["by"] for m in ident.relocations][-1:] == ["scan"], ident.relocations
    assert ident.status("k_sun_planet") == "NOT DETERMINED"
    assert ident.status("sun_fault") != "NOT DETERMINED"
    rows = {r["excitation"]: r for r in ident.splits}
    assert rows[SPLIT_CALIBRATED]["values"]["k_sun_planet"] < 4.5e8
    lo, hi = ident.interval("k_sun_planet")
    assert all(lo <= r["values"]["k_sun_planet"] <= hi for r in ident.splits if r["accepted"])


def test_shape_profile_keeps_the_shapes_a_model_form_error_cannot_reject(monkeypatch):
    """The union rule of dtwin.identify.severity on stand-in fits: a shape whose ‖r‖² exceeds
    the best by less than max(χ²₁ s² κ, ‖r‖² − E) joins the interval; severity and peak loss map
    through each shape's own ramp (dtwin.model.faults.peak_stiffness_loss), the peak relative to the
    mean mesh stiffness and its interval from the waveform's largest to its smallest value
    (ISO 6336: c_γ = (0.75 ε + 0.25) c')."""
    import equinox as eqx
    import jax.numpy as jnp

    from dtwin.identify import severity
    from dtwin.identify.severity import _estimate, _fault_index
    from dtwin.model.faults import peak_stiffness_loss
    from dtwin.spec.build import build_twin

    # the stand-ins carry no problem to simulate: the healthy-tooth test (checked on the bench
    # records in test_calibrate.py) rejects a healthy tooth here
    monkeypatch.setattr(severity, "_healthy_accepted", lambda *a: False)
    from dtwin.model.registry import lookup
    from dtwin.spec import preset

    tw = lookup("sun_fault").address.ensure(build_twin(preset("paper-sim")))
    k = _fault_index(tw, "sun")

    def stand_in(ramp, loss, sev, iv, lack):
        twin = eqx.tree_at(lambda t: t.parts[k].fault.ramp, tw, jnp.asarray(ramp))
        unc = types.SimpleNamespace(interval=np.array([iv]), s2=0.08, kappa=1.8, widened=1.0,
                                    lack_of_fit=lack, profiled=(), not_determined={})
        return (ramp, types.SimpleNamespace(
            loss=loss, names=("sun_fault",), values={"sun_fault": sev}, uncertainty=unc,
            problem=types.SimpleNamespace(twin=twin), widened=1.0,
            status=lambda n: "ok"))

    def peak(ramp, s, reference="instant"):
        f = eqx.tree_at(lambda f: f.fault.ramp, tw.parts[k], jnp.asarray(ramp)).fault
        return float(peak_stiffness_loss(eqx.tree_at(lambda f: f.severity, f, jnp.asarray(s)),
                                         tw.lp, reference=reference))

    # at the noise (lack 1): χ²₁ s² κ = 0.55 in ‖r‖²; a shape 2 × 0.5 = 1.0 worse is rejected
    est = _estimate("sun", [stand_in(0.05, 60.5, 0.17, (0.15, 0.20), 1.0),
                            stand_in(0.3, 60.0, 0.13, (0.11, 0.16), 1.0)])
    assert est.ramp == 0.3 and est.interval == pytest.approx((0.11, 0.16))
    assert est.peak_loss == pytest.approx(peak(0.3, 0.13))
    assert [r["accepted"] for r in est.shapes] == [False, True]
    # 25 % above the noise: ‖r‖² − E = 160 (1 − 1/1.25) = 32 > 2 × 6, so the sharp shape stays
    est = _estimate("sun", [stand_in(0.05, 86.0, 0.75, (0.72, 0.79), 1.3),
                            stand_in(0.3, 80.0, 0.44, (0.37, 0.50), 1.25)])
    assert est.interval == pytest.approx((0.37, 0.79))
    # the peak's interval: lower bound against the waveform's largest value, upper against its
    # smallest (the healthy waveform at the faulty tooth is not known)
    assert est.peak_interval == pytest.approx((peak(0.3, 0.37, "max"), peak(0.05, 0.79, "min")))
    eps = float(tw.lp.eps_sp)
    assert peak(0.05, 0.79, "min") == pytest.approx(0.79, rel=1e-3)
    assert peak(0.05, 0.75, "mean") == pytest.approx(0.75 / (0.75 * eps + 0.25), rel=1e-3)
    assert est.method == "gaussian + loss shapes"
