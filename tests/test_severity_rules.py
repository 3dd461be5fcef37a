"""The pieces of severity's honest intervals, each against something outside the code: the
delete-one-band jackknife against Monte Carlo coverage (a model-form error coherent over each
band, and noise alone), the loss's `spread` against the closed-form area of its window, and
the low band against the record's own spectrum."""

from __future__ import annotations

import numpy as np
import pytest
from _gearboxes import FOUR_PLANET


def _coverage(tau: float, sigma: float, trials: int, seed: int):
    """Coverage of the band jackknife's and of the independent-points 95 % intervals for a
    least-squares slope whose data carry a random offset per band (model-form error, sd
    `tau`, proportional to the sensitivity as a wrong shape's would be) and white noise."""
    from dtwin.identify.uncertainty import Z95, band_jackknife

    rng = np.random.default_rng(seed)
    n_bands, n = 5, 200
    groups = np.repeat(np.arange(n_bands), n)
    hits_jk = hits_iid = 0
    for _ in range(trials):
        x = np.concatenate([rng.uniform(0.5, 1.5, n) * s for s in rng.uniform(0.3, 1.0, n_bands)])
        y = 2.0 * x + np.repeat(rng.normal(0.0, tau, n_bands), n) * x \
            + rng.normal(0.0, sigma, n_bands * n)
        th = float(np.sum(x * y) / np.sum(x * x))
        r = th * x - y
        half, loo = band_jackknife(np.array([th]), r, x[:, None], groups)
        assert loo.shape == (n_bands, 1)
        sd = np.sqrt(np.sum(r * r) / (r.size - 1) / np.sum(x * x))
        hits_jk += abs(th - 2.0) <= half[0]
        hits_iid += abs(th - 2.0) <= Z95 * sd
    return hits_jk / trials, hits_iid / trials


def test_band_jackknife_covers_a_band_coherent_model_error():
    """Offsets coherent over each band: the interval that counts every point as independent
    holds the truth far less than 95 % of the time; the band jackknife (t with B − 1 dof)
    holds it about 95 % (measured 0.92–0.93 over 2000 trials)."""
    jk, iid = _coverage(tau=0.3, sigma=1.0, trials=400, seed=0)
    assert jk >= 0.88
    assert iid <= 0.6


def test_band_jackknife_under_noise_alone():
    """No model-form error: the jackknife's coverage stays at its nominal 95 %."""
    jk, iid = _coverage(tau=0.0, sigma=1.0, trials=400, seed=1)
    assert jk == pytest.approx(0.95, abs=0.035)
    assert iid == pytest.approx(0.95, abs=0.035)


def test_band_jackknife_needs_three_bands():
    from dtwin.identify.uncertainty import band_jackknife

    half, _ = band_jackknife(np.zeros(1), np.ones(4), np.ones((4, 1)), np.array([0, 0, 1, 1]))
    assert np.isnan(half).all()


def test_spread_widens_the_loss_by_its_closed_form_area():
    """A loss spread `d` cycles beyond the contact either side (``d < 0``: confined to the
    contact's middle) removes stiffness over ``eps + 2d`` cycles (the window's area: a logistic
    box of edges ``ramp`` ≪ its width has area equal to its width), and the peak of a sharp
    missing tooth is its severity times the window at its centre, in single contact."""
    import jax.numpy as jnp

    from dtwin.model.faults import MissingTooth, peak_stiffness_loss

    eps = 1.6
    u = jnp.linspace(-8.0, 10.0, 180_001)
    du = float(u[1] - u[0])
    for spread in (-0.45, -0.2, 0.0, 0.5, 1.0, 2.0):  # negative: confined to the middle
        f = MissingTooth(0.4, ramp=0.05, spread=spread)
        area = float(jnp.sum(f.window(u, eps))) * du
        assert area == pytest.approx(eps + 2 * spread, rel=1e-4)
        # at the window's centre (single contact), both edges' sigmoids short of 1
        edge = 1.0 / (1.0 + np.exp(-(0.5 * eps + spread) / 0.05))
        assert float(peak_stiffness_loss(f, eps)) == pytest.approx(0.4 * edge ** 2, rel=1e-6)


def test_spread_zero_is_the_former_loss_bit_for_bit():
    import jax.numpy as jnp

    from dtwin.model.faults import MissingTooth, _smooth_box

    u = jnp.linspace(-1.0, 3.0, 4001)
    f = MissingTooth(0.4, ramp=0.2)
    assert bool(jnp.all(f.window(u, 1.6) == _smooth_box(u, 0.0, 1.6, 0.2)))


def test_spread_is_checked():
    from dtwin.errors import SpecError
    from dtwin.model.faults import MAX_SPREAD, MIN_SPREAD, MissingTooth

    for bad in (MIN_SPREAD - 0.01, MAX_SPREAD + 0.01):
        with pytest.raises(SpecError, match="spread"):
            MissingTooth(0.4, spread=bad)
    MissingTooth(0.4, spread=MIN_SPREAD)


@pytest.mark.parametrize("v_hat, sigma", [(0.02, 0.01), (0.5, 0.05), (0.97, 0.02)])
def test_profile_interval_edges_against_the_closed_form(v_hat, sigma):
    """The profile-likelihood interval of a bounded severity (used near a bound) on a loss
    whose profile is known: ``rss(v) = ((v − v̂)/σ)²`` gives the edges ``v̂ ± σ √χ²₀.₉₅`` clipped
    to [0, 1]. A coarse grid alone puts an edge anywhere within 1/24 of the range (0.02 off for
    v̂ = 0.02); refined between the bracketing grid values and interpolated, within 0.002."""
    from dtwin.identify.params import ParameterSet
    from dtwin.identify.uncertainty import CHI2_95, _profile_interval

    pset = ParameterSet.build(["sun_fault"], initial={"sun_fault": 0.3})
    theta = pset.theta([v_hat])

    def profile_fn(thetas):
        v = np.array([float(pset.values(t)[0]) for t in np.asarray(thetas)])
        return ((v - v_hat) / sigma)[:, None]

    iv, (th_best, rss_best) = _profile_interval(pset, theta, np.zeros(1), np.ones((1, 1)), 0,
                                                1.0, profile_fn, 1)
    # the lowest profile point: the optimum's, within the grid (no better point)
    assert rss_best >= 0.0 and abs(float(pset.values(th_best)[0]) - v_hat) < 0.05
    half = sigma * np.sqrt(CHI2_95)
    want = [max(0.0, v_hat - half), min(1.0, v_hat + half)]
    np.testing.assert_allclose(iv, want, atol=2e-3)


def test_a_pit_is_read_by_the_shape_confined_to_the_contacts_middle():
    """A pitting band (dtwin.model.faults.Pitting, 0.3–0.7 of the contact path: another fault model
    than the missing tooth the severity fit uses) on a record whose twin keeps 30 stiffness
    harmonics and a 0.5 µm transmission error (the fitted twin: 12, none) and runs 1 % slow:
    of the two shapes, the loss over the whole contact and the one confined to its middle
    (spread MIN_SPREAD), the record rejects the first and accepts the second, whose peak
    stiffness loss lies within 20 % of the pit's and whose interval holds it.
    Measured: 30.4 % [20.1, 53.9] for 34.2 %; the whole-contact shape's loss 3.5× larger."""
    from dtwin.identify.severity import estimate_severity
    from dtwin.model.faults import MIN_SPREAD, Pitting, peak_stiffness_loss
    from dtwin.model.parts.imperfections import TransmissionError
    from dtwin.simulation.simulate import DAQ, simulate
    from dtwin.spec import preset
    from dtwin.spec.build import build_twin

    spec = preset("paper-sim")
    pit = Pitting(0.5, location="sun")
    tw = build_twin(spec, kind="torsional", f_sun=29.7, n_harmonics=30, faults=(pit,),
                    extra_parts=(TransmissionError(np.float64(5e-7)),))
    truth = float(peak_stiffness_loss(pit, tw.lp, reference="instant"))
    rec = simulate(tw, duration=0.5, f_sun=29.7, daq=DAQ(sample_rate=5000.0, snr_db=20.0),
                   discard=0.05, seed=3).to_record()
    est = estimate_severity(rec, spec, "sun", initial_severity=0.35, max_steps=25,
                            method="spectrum", ramps=[(0.05, 0.0), (0.05, MIN_SPREAD)], kind="torsional")
    print(est.summary())
    print(est.shapes_table())
    whole, middle = est.shapes
    assert middle["accepted"] and not whole["accepted"] and middle["loss"] < whole["loss"]
    assert est.spread == MIN_SPREAD
    assert abs(est.peak_loss - truth) <= 0.2 * truth
    assert est.peak_interval[0] <= truth <= est.peak_interval[1]
    table = est.shapes_table().splitlines()
    assert len(table) == 3 and "mid-contact" in table[2] and "rejected" in table[1]


def test_a_severity_is_fitted_with_the_translational_twin_unless_asked():
    """dtwin.spec.build.SEVERITY_KIND: a spec's severity fit builds the translational twin whatever
    kind the spec names; where the spec was calibrated with the torsional twin the estimate's
    note says so; a kind asked for, or a twin given, is kept."""
    from dtwin.identify.severity import _twin_kind
    from dtwin.spec import load_spec, preset, spec_to_dict
    from dtwin.spec.build import SEVERITY_KIND, build_twin

    assert SEVERITY_KIND == "translational"
    data = spec_to_dict(preset("paper-sim"))
    data.pop("source", None)
    data["model"] = {"kind": "torsional"}
    plain = load_spec(data)
    assert _twin_kind(plain, None) == ("translational", "")
    cal = load_spec({**data, "calibration": {"records": "healthy.csv"}})
    kind, note = _twin_kind(cal, None)
    assert kind == "translational" and "calibrated with" in note and "--model torsional" in note
    assert _twin_kind(cal, "torsional") == ("torsional", "")
    assert _twin_kind(build_twin(plain), None) == (None, "")


def test_the_low_band_by_default_for_sun_and_ring_faults_on_steady_records(monkeypatch):
    """``low_band=None``: the observation of a sun or ring fault's severity starts at the low
    band (0.8 N f_c), a planet fault's at its first mesh band (LOW_BAND_LOCATIONS); asked for,
    a planet fault gets it too."""
    from importlib import import_module

    from dtwin.identify.severity import LOW_BAND_START, estimate_severity
    from dtwin.model.kinematics import Kinematics
    from dtwin.simulation.simulate import DAQ, simulate
    from dtwin.spec import preset
    from dtwin.spec.build import build_twin

    severity = import_module("dtwin.identify.severity")
    spec = preset("paper-sim")
    tw = build_twin(spec, kind="torsional")
    rec = simulate(tw, duration=0.5, f_sun=30.0, daq=DAQ(sample_rate=5000.0, snr_db=20.0),
                   discard=0.05, seed=1).to_record()
    low = LOW_BAND_START * 3 * Kinematics.from_gear_set(tw.lp, 30.0).f_carrier
    seen = []

    class Stop(Exception):
        pass

    def capture(*a, problem, **k):
        seen.append(float(np.min(np.asarray(problem.observations[0].freqs))))
        raise Stop

    monkeypatch.setattr(severity, "fit", capture)
    for location, low_band, has_low in (("sun", None, True), ("ring", None, True),
                                        ("planet", None, False), ("planet", True, True),
                                        ("sun", False, False)):
        with pytest.raises(Stop):
            estimate_severity(rec, spec, location, low_band=low_band, kind="torsional",
                              f_sun=30.0, method="spectrum")
        assert (seen[-1] < 2 * low) == has_low, (location, low_band, seen[-1], low)


def test_stiffness_split_of_a_calibrated_spec():
    """dtwin.identify.split.stiffness_split: the calibrated spec with every transmission-error
    harmonic at 0 m and a flat response at its knots' mean level, window and damping as
    calibrated; none for an uncalibrated spec or a twin; the spec handed in is not modified."""
    from pathlib import Path

    from dtwin.identify.split import stiffness_split
    from dtwin.spec import load_spec
    from dtwin.spec.build import build_twin

    spec = load_spec(Path(__file__).parent / "data" / "four_planet_calibrated.toml")
    frf = list(spec["sensor"]["frf_db"])
    other = stiffness_split(spec)
    assert spec["sensor"]["frf_db"] == frf and any(spec["mesh"]["excitation_ring_cos"])
    assert other["sensor"]["frf_db"] == pytest.approx([np.mean(frf)] * len(frf))
    for k in ("excitation_ring_cos", "excitation_ring_sin", "excitation_sun_cos",
              "excitation_sun_sin"):
        assert not any(other["mesh"][k])
    assert other["sensor"]["window_harmonics"] == spec["sensor"]["window_harmonics"]
    assert other["damping"]["zeta_mesh"] == spec["damping"]["zeta_mesh"]
    assert stiffness_split(other) is None  # nothing left to split
    assert stiffness_split(load_spec(FOUR_PLANET)) is None
    assert stiffness_split(build_twin(spec)) is None


#: In ``make test-all`` only (issue "A diagnosis in a minute", item 8: ~280 s of ``make test``,
#: compilation mostly). ``make test`` keeps each piece of it: the same crack record read
#: through the split it prefers, the calibrated split rejected and the peak loss within 25 %
#: (tests/test_split.py, `dtwin identify`); severity fitting both splits as rows of its shape
#: table and reporting the one of least loss (tests/test_severity_independent.py,
#: ``test_sun_fault_peak_loss_on_independent_record``); and the one rule that accepts or rejects
#: every row — shape, split or flank alike (`dtwin.identify.severity._estimate`) — with rows
#: rejected (the pit's whole-contact shape above, the wrong flanks below).
@pytest.mark.slow
def test_a_calibrations_split_the_faulty_record_rejects_is_not_reported():
    """A four-planet gearbox whose calibration (tests/data/four_planet_calibrated.toml, fitted
    on a healthy record by dtwin calibrate) raised its sensor response 19 dB over the band and
    cancelled part of the ring mesh's stiffness excitation with a transmission error: the
    healthy record cannot tell that from a flat response, but a sun root crack's sidebands pass
    the response uncancelled and read 2.4× small through it. The record (the truth's twin: 16
    stiffness harmonics where the fitted twin has 12, a root crack where the fit has a missing
    tooth's loss, no transmission error, a flat response, 30 dB noise) rejects that split; the
    stiffness waveform's excitation with a flat response is reported, its peak stiffness loss
    within 25 % of the crack's and its interval holding it. Measured (4 s records): 33.0 %
    against 14.8 % with the calibrated split alone, truth 36.0 %."""
    from pathlib import Path

    from dtwin.identify.severity import estimate_severity
    from dtwin.identify.split import SPLIT_CALIBRATED, SPLIT_STIFFNESS
    from dtwin.model.faults import RootCrack, peak_stiffness_loss
    from dtwin.simulation.simulate import DAQ, simulate
    from dtwin.spec import load_spec
    from dtwin.spec.build import build_twin

    crack = RootCrack(0.4, location="sun", tooth=2)
    tw = build_twin(load_spec(FOUR_PLANET), kind="translational", n_harmonics=16,
                    faults=(crack,))
    truth = float(peak_stiffness_loss(crack, tw.lp, reference="instant"))
    rec = simulate(tw, duration=2.0, f_sun=25.0, daq=DAQ(sample_rate=10000.0, snr_db=30.0),
                   discard=0.2, seed=540).to_record()
    cal = load_spec(Path(__file__).parent / "data" / "four_planet_calibrated.toml")
    est = estimate_severity(rec, cal, "sun", method="spectrum")
    print(est.summary())
    print(est.shapes_table())
    rows = {r["excitation"]: r for r in est.shapes}
    assert set(rows) == {SPLIT_CALIBRATED, SPLIT_STIFFNESS}
    assert est.excitation == SPLIT_STIFFNESS and est.to_dict()["excitation"] == SPLIT_STIFFNESS
    assert not rows[SPLIT_CALIBRATED]["accepted"]
    assert rows[SPLIT_CALIBRATED]["peak_stiffness_loss"] < 0.6 * truth  # what it read
    assert abs(est.peak_loss - truth) <= 0.25 * truth
    assert est.peak_interval[0] <= truth <= est.peak_interval[1]
    assert "excitation and response" in est.shapes_table()


def _planet_pit_estimate(flanks=None):
    """A planet tooth pitted on the flank that meets the ring (four-planet 24/36/96 box, planet
    1; the record's twin has 16 stiffness harmonics where the fitted one has 12, pitting where
    the fit has a missing tooth's loss, 30 dB noise), its severity estimated with the user's
    spec, which names no flank, on `flanks` (None: the default, every flank): the estimate, the
    pit's peak stiffness loss and the spec."""
    from dtwin.identify.severity import estimate_severity
    from dtwin.model.faults import Pitting, peak_stiffness_loss
    from dtwin.simulation.simulate import DAQ, simulate
    from dtwin.spec import load_spec
    from dtwin.spec.build import build_twin

    pit = Pitting(0.4, location="planet", planet=1, tooth=5, flank="ring")
    tw = build_twin(load_spec(FOUR_PLANET), kind="translational", n_harmonics=16,
                    faults=(pit,))
    truth = float(peak_stiffness_loss(pit, tw.lp, reference="instant"))
    rec = simulate(tw, duration=2.0, f_sun=25.0, daq=DAQ(sample_rate=10000.0, snr_db=30.0),
                   discard=0.2, seed=541).to_record()
    spec = load_spec(FOUR_PLANET)
    est = estimate_severity(rec, spec, "planet", flanks=flanks, method="spectrum")
    print(est.summary())
    print(est.shapes_table())
    return est, truth, spec


def _check_ring_flank_reported(est, truth, spec, wrong_flanks):
    rows = {r["flank"]: r for r in est.shapes}
    assert set(rows) == {"ring", *wrong_flanks}
    assert est.flank == "ring" and est.to_dict()["flank"] == "ring"
    assert "(ring flank)" in est.summary() and "flank" in est.shapes_table()
    assert [f for f, r in rows.items() if r["accepted"]] == ["ring"]
    for wrong in wrong_flanks:
        assert rows[wrong]["peak_stiffness_loss"] < 0.5 * truth  # what it would have read
    assert est.peak_loss > 0.65 * truth
    assert spec["faults"] == []  # the user's spec is not modified
    if not est.peak_interval[0] <= truth <= est.peak_interval[1]:
        # measured 2026-11-30: 28.8 % [14.1, 33.4] for 40.0 % (the pit lies where a single
        # pair carries the load, so its instant peak is 1.7× its peak against the mean
        # stiffness, 23.5 %, which the interval holds)
        pytest.xfail("issue 'One fault depth', item 5 (open): in the truth's terms the spectrum "
                     f"fit's interval {est.peak_interval} misses the pit's peak loss {truth:.3f}")


def test_a_planet_fault_is_fitted_on_the_flank_the_record_prefers():
    """CI form (issue "A diagnosis in a minute", item 8): the ring flank against both flanks,
    the fit that was the answer before the flanks were fitted (each flank is a compiled fit of
    its own, ~1/3 of the full form's time). Every fit is the full form's (each flank's fit is
    independent of the others', and the rows rejected do not enter the interval), so the same
    numbers are asserted: the record rejects both flanks, which read the fault about half, and
    the ring flank is reported with the truth inside its interval. Measured (2026-11-30,
    peaks against the mean stiffness): ring 17.0 % [14.1, 33.4], loss 104.4; both flanks 10.9 %
    (186.0); truth 23.5 %. In the truth's own terms (the stiffness at that instant) ring 28.8 %,
    both 16.3 %, truth 40.0 %, which the interval misses (an expected failure, checked last). That the
    default fits every flank (PLANET_FLANKS) is checked without a fit below
    (``test_flanks_are_a_planet_faults_and_a_named_flank_is_taken_at_its_word``), all three
    in the full form (slow)."""
    _check_ring_flank_reported(*_planet_pit_estimate(flanks=("both", "ring")),
                               wrong_flanks=("both",))


@pytest.mark.slow
def test_a_planet_fault_is_fitted_on_every_flank_and_the_record_prefers_the_ring():
    """Full form. The user's spec names no flank, so the severity is fitted on both flanks, on
    the sun's and on the ring's (PLANET_FLANKS): the record rejects the two wrong ones, whose
    fits read the fault 2–4× small, and the ring flank is reported with the truth inside its
    interval. Measured (2 s record, 2026-11-30): ring 17.0 % [14.1, 33.4], loss 104.4; both
    flanks 10.9 % (loss 186.0); sun flank 6.0 % (537.8); truth 23.5 % (earlier: ring 17.4 %,
    both 9.2 %, sun 4.2 %). Before the flanks were fitted, the both-flank fit was the
    answer."""
    from dtwin.identify.severity import PLANET_FLANKS

    est, truth, spec = _planet_pit_estimate()
    assert {r["flank"] for r in est.shapes} == set(PLANET_FLANKS)
    _check_ring_flank_reported(est, truth, spec, wrong_flanks=("both", "sun"))


def test_flanks_are_a_planet_faults_and_a_named_flank_is_taken_at_its_word():
    """flanks=None fits every flank for a planet fault whose spec names none, the spec's flank
    where it names one, and none for a sun or ring fault or a twin; flanks for a sun fault, or
    an unknown flank, is a clear error before anything is fitted."""
    from dtwin.errors import SettingsError
    from dtwin.identify.severity import PLANET_FLANKS, _flanks
    from dtwin.spec import load_spec
    from dtwin.spec.build import build_twin

    plain = load_spec(FOUR_PLANET)
    named = load_spec({**FOUR_PLANET, "faults": [{"location": "planet", "type": "pitting",
                                                  "severity": 0.0, "flank": "sun"}]})
    unnamed = load_spec({**FOUR_PLANET, "faults": [{"location": "planet", "type": "pitting",
                                                    "severity": 0.0}]})
    assert _flanks(plain, "planet", None) == PLANET_FLANKS
    assert _flanks(unnamed, "planet", None) == PLANET_FLANKS
    assert _flanks(named, "planet", None) == (None,)
    assert _flanks(named, "planet", True) == PLANET_FLANKS
    assert _flanks(plain, "planet", ["ring", "sun", "ring"]) == ("ring", "sun")
    assert _flanks(plain, "sun", None) == (None,) == _flanks(plain, "planet", False)
    assert _flanks(build_twin(plain), "planet", None) == (None,)
    with pytest.raises(SettingsError, match="planet tooth"):
        _flanks(plain, "sun", True)
    with pytest.raises(SettingsError, match="flanks must be some of"):
        _flanks(plain, "planet", ["left"])
