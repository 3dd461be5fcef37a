"""Discovery on records of a gearbox dtwin did not simulate (issue #19, items 3 and 4).

The records in ``../shared/independent/`` come from an independent simulator (its own stiffness
waveform, fault model, sensor path and noise); the twin is the user's ``gearbox.toml``
calibrated on ``baseline-1.csv`` alone (:func:`dtwin.identify.calibrate.calibrate`, session
fixture ``independent_calibrated_spec``), and every record below is one the calibration never
saw. ``truth.json`` says what each record holds; the claims are the group the search names,
the held-out gap it closes (≤ 3 dB after, or ≥ 70 % of the base twin's gap closed; the gap of
the full twin with the effect, nothing refitted on the scored half), the frequency it locates
for a load fluctuation (2.1 Hz in the truth), and that a tone unrelated to the gearbox is left
unexplained. CI runs four records (a sun fault, the load fluctuation, the tone, the healthy
baseline-2); the others are ``slow``.
"""

from __future__ import annotations

import pytest
from _independent import IND, needs_independent

pytestmark = needs_independent

#: the look-alike group each hidden effect belongs to (docs/discovery.md)
GROUP = {"sun-fault-0.15": "sun_rotation", "sun-fault-0.30": "sun_rotation",
         "sun-fault-0.60": "sun_rotation", "sun-fault-0.90": "sun_rotation",
         "sun-ecc": "sun_rotation", "planet-fault": "planet_fault",
         "ring-fault": "carrier_sidebands", "spacing": "carrier_sidebands",
         "load-fluct": "located_modulation"}

_RESULTS: dict = {}


#: CI form: the first step, two candidates refit, 200 bootstrap draws (the slow form: the
#: default settings, n_boot 400, the two best of the covering candidates by score refit)
QUICK = dict(max_steps=1, max_refit=2, n_boot=200)
FULL = dict(max_steps=1)


def _discover(name, spec_path, quick=True):
    from dtwin.identify.discover import DiscoverySettings, discover
    from dtwin.io.readers import read_record

    key = (name, quick)
    if key not in _RESULTS:
        _RESULTS[key] = discover(read_record(IND / f"{name}.csv"), spec_path,
                                 settings=DiscoverySettings(**(QUICK if quick else FULL)))
    return _RESULTS[key]


def _lines_against_healthy(name):
    """Residual lines of record `name` against the healthy ``baseline-1`` spectrum (same machine,
    same sensor: a reference no twin made), kinematics at the nominal speed."""
    import numpy as np

    from dtwin.identify.lines import Kinematics, residual_lines
    from dtwin.io.readers import read_record
    from dtwin.signal.spectrum import amplitude_spectrum
    from dtwin.spec import load_spec

    kin = Kinematics.from_spec(load_spec(IND / "gearbox.toml"))
    spectra = []
    for n in (name, "baseline-1"):
        x = np.asarray(read_record(IND / f"{n}.csv").channel(0), float)
        f, a = amplitude_spectrum(x - x.mean(), 5000.0, "hann")
        spectra.append(np.asarray(a))
    f = np.asarray(f)
    tol = 0.25 * (f[1] - f[0])
    return residual_lines(f, spectra[0], spectra[1], kin, f_max=2500.0), kin, tol


@pytest.mark.parametrize("name, effect, symbol", [
    ("sun-fault-0.60", "sun_local_fault", "fs/3"), ("planet-fault", "planet_local_fault", "fp"),
    ("ring-fault", "ring_local_fault", "3fc")])
def test_fault_signature_covers_its_comb(name, effect, symbol):
    """A tooth fault's lines — the low-frequency impulse comb and the mesh sidebands — lie on
    its effect's signature, and the comb is found as one family whose chance of arising from
    as many random lines is negligible."""
    from dtwin.identify.discover import coverage
    from dtwin.identify.discover import effects as E
    from dtwin.identify.lines import find_combs, label_combs

    lines, kin, tol = _lines_against_healthy(name)
    e = next(x for x in E.registered_effects() if x.name == effect)
    cov, matched = coverage(e, kin, lines, tol, 2500.0)
    assert cov >= 0.8, cov
    assert any(r.frequency < 0.9 * kin.f_mesh for r in matched)  # the low-frequency comb
    assert any(abs(r.frequency - kin.f_mesh) < 60 for r in matched)  # mesh sidebands
    combs = find_combs(lines, kin, tol, 2500.0)
    assert combs and combs[0].symbol == symbol and combs[0].chance < 1e-6, [c.text for c in combs]
    assert len(combs[0].members) >= 10
    labelled = label_combs(lines, combs)
    # no line of the comb is left as "no kinematic match"
    members = {m[0] for m in combs[0].members}
    assert all(r.text != "no kinematic match" for r in labelled if r.frequency in members)


def test_modulation_located_and_tone_not_named():
    """The load fluctuation's family (2.1 Hz and its sidebands) is located at 2.1 ± 0.05 Hz;
    the unrelated tone forms no comb and no modulation."""
    from dtwin.identify.lines import find_combs, find_modulation

    lines, kin, tol = _lines_against_healthy("load-fluct")
    mod = find_modulation(lines, kin, tol, 2500.0)
    assert mod is not None and abs(mod.f_x - 2.1) <= 0.05 and mod.chance < 1e-6, mod
    for name in ("tone", "baseline-2"):
        lines, kin, tol = _lines_against_healthy(name)
        assert find_combs(lines, kin, tol, 2500.0) == []
        assert find_modulation(lines, kin, tol, 2500.0) is None
        tone = [r for r in lines if abs(r.frequency - 1111.3) < 0.5]
        assert name != "tone" or (tone and tone[0].text == "no kinematic match")


def _truth_effect(name: str) -> dict:
    import json

    return json.loads((IND / "truth.json").read_text())["records"][name]["effects"][0]


def _gap_closed(res) -> tuple[float, float, float]:
    before, after = res.initial_gap.total, res.final_gap.total
    return before, after, (before - after) / before


def _check_group(name, spec_path, quick=True, gap=True):
    res = _discover(name, spec_path, quick)
    assert res.steps, f"{name}: nothing added ({res.stop_reason})"
    step = res.steps[0]
    assert step.group == GROUP[name], (name, step.group, step.named)
    if gap:
        _check_gap(res, name)
    return res


def _check_gap(res, name):
    before, after, closed = _gap_closed(res)
    assert after <= 3.0 or closed >= 0.7, (name, before, after, closed)


#: records whose gap target (≤ 3 dB after or ≥ 70 % closed) is not met, with the measured
#: values (benchmarks/history.md, "Discovery on the independent records"): the target stays as a strict xfail
GAP_NOT_MET = {
    "planet-fault": "corrected record, gap scored from 0.8 N fc: planet_local_fault alone, "
                    "17.92 → 7.19 dB (60 % closed); the fault's mesh sidebands stay short "
                    "(scored from 0 Hz: 18.57 → 6.91 dB with a false carrier_sidebands; the "
                    "earlier record, with a comb on k fp no torque-balanced gearbox makes: "
                    "20.32 → 14.99 dB)",
}


@pytest.mark.parametrize("name", ["sun-fault-0.60"])
def test_fault_record_names_its_group(name, independent_calibrated_spec):
    res = _check_group(name, independent_calibrated_spec)
    # the base twin's residual: the sun fault's impulse comb k fs/3 ± n fc is labelled as one
    # family (it was ~20 lines of "no kinematic match"), few lines are left without a label
    base = [r for r in res.residuals[0] if r.side == "measured"]
    assert sum("fs/3" in r.comb for r in base) >= 10, [r.text for r in base]
    assert sum(r.text == "no kinematic match" for r in base) <= 3, [r.text for r in base]
    # the model's simulations at constant speed are one hunting period, tiled and checked
    # (DiscoverySettings.periodic): the base twin and the sun candidates' responses
    import collections
    import sys

    models = sys.modules["dtwin.identify.discover.model"]._MODEL_CACHE.values()
    methods = sum((model.methods for model in models), collections.Counter())
    assert methods["periodic"] >= 2, methods


def test_load_fluctuation_is_located(independent_calibrated_spec):
    res = _check_group("load-fluct", independent_calibrated_spec, gap=False)
    step = res.steps[0]
    f_x = res.modulation.f_x if res.modulation is not None else None
    assert "load/speed fluctuation at" in step.summary, step.summary
    located = float(step.summary.split(" at ")[1].split(" Hz")[0])
    assert abs(located - 2.1) <= 0.05, (located, f_x)
    # a line left near f_x would be the added fluctuation's, not "no kinematic match"
    left = [r for r in res.unexplained if abs(r.frequency - located) < 0.5]
    assert all("added in step 1" in r.text for r in left), [r.text for r in left]
    # the torque fluctuation, estimated from the mesh sidebands (the f_x line itself goes
    # through the housing's mounts, a path of its own): truth.json's 6 % of the 40 N·m load
    from dtwin.spec import load_spec

    truth = _truth_effect("load-fluct")
    amp = truth["fraction_of_load"] * load_spec(IND / "gearbox.toml")["operating"]["load_torque"]
    lo, hi = step.main["interval"]
    if not lo <= amp <= hi:
        # within 30 % still, so a broken estimate fails; the interval's miss is reported
        assert abs(step.main["value"] / amp - 1.0) < 0.3, (step.main, amp)
        pytest.xfail(LOAD_FLUCT_BIAS.format(step.main["value"], lo, hi, amp))
    assert abs(step.main["value"] / amp - 1.0) < 0.25, (step.main, amp)


#: The torque estimate rests on the mesh sidebands seen through the calibrated path. It was
#: 2.40 [2.14, 2.69] N·m for 2.4 while the twin's anti-aliasing filter was 6 dB down at 0.40 fs;
#: with the filter flat to 0.45 fs (the spec's pass band) and the calibration made again with
#: it, 3.03 [2.64, 3.40]: the calibrated path near 4 fm (2 kHz; its band still 10 dB off after
#: calibration) moves the sidebands' weight, and the interval, which holds the noise only,
#: misses the truth. A known model-form error, not yet closed.
LOAD_FLUCT_BIAS = ("torque fluctuation {:.3g} [{:.3g}, {:.3g}] N·m misses the truth {:.3g}: "
                   "the calibrated path's error near 4 fm, not in the interval")


@pytest.mark.parametrize("name, effect", [("sun-fault-0.60", "sun_local_fault"),
                                          ("load-fluct", "located_modulation")])
def test_true_candidate_ranks_first_by_score(name, effect, independent_calibrated_spec):
    """Screening (issue #21): the candidate of the record's hidden effect (truth.json) has the
    largest score at zero amplitude among all candidates scored in the first step — the located
    modulation scored at the frequency located in the record —; every candidate reports its
    score, and those not refit say so."""
    import math

    res = _discover(name, independent_calibrated_spec)
    cands = res.steps[0].candidates if res.steps else res.last_candidates
    assert all(math.isfinite(c.score) and c.score_rank >= 1 for c in cands)
    first = min(cands, key=lambda c: c.score_rank)
    assert first.name == effect, [(c.name, c.score, c.score_rank) for c in cands]
    assert sorted(c.score_rank for c in cands) == list(range(1, len(cands) + 1))
    # the best max_refit are refit, and the best of another group when those are all of one
    top = [c for c in cands if c.score_rank <= QUICK["max_refit"]]
    groups = {c.group for c in top}
    others = sorted((c for c in cands if c.group not in groups), key=lambda c: c.score_rank)
    extra = others[0].name if len(top) >= 2 and len(groups) == 1 and others else None
    for c in cands:
        if c.score_rank > QUICK["max_refit"] and c.name != extra:
            assert c.screened == (f"screened out, score {c.score:.3g} ({c.score_df} df), "
                                  f"rank {c.score_rank}")
            assert math.isnan(c.p_value)
        else:
            assert c.screened is None and math.isfinite(c.p_value)


def test_load_fluctuation_gap_target(independent_calibrated_spec):
    res = _discover("load-fluct", independent_calibrated_spec)
    assert res.steps
    _check_gap(res, "load-fluct")


def test_tone_is_left_unexplained(independent_calibrated_spec):
    res = _discover("tone", independent_calibrated_spec)
    for step in res.steps:
        assert all(abs(r.frequency - 1111.3) > 0.5 for r in step.matched_lines), step.named
    tone = [r for r in res.unexplained if abs(r.frequency - 1111.3) < 0.5]
    assert tone and tone[0].text == "no kinematic match", [r.text for r in tone]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(GROUP))
def test_hidden_effect_names_its_group_slow(name, independent_calibrated_spec):
    _check_group(name, independent_calibrated_spec, quick=False, gap=name not in GAP_NOT_MET)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(GAP_NOT_MET))
@pytest.mark.xfail(strict=True, reason="gap target not met (GAP_NOT_MET)")
def test_hidden_effect_gap_target_slow(name, independent_calibrated_spec):
    _check_gap(_discover(name, independent_calibrated_spec, quick=False), name)


@pytest.mark.slow
def test_planet_fault_is_named_alone_slow(independent_calibrated_spec):
    """The planet-fault record, default settings (up to three steps): the planet fault and
    nothing else. Its own f_c and 2 f_c lines, which the twin leaves 19–27 dB short, lie below
    the scored band (0.8 N f_c, docs/discovery.md §1) and no longer make the 1 f_c load
    fluctuation a second step."""
    from dtwin.identify.discover import DiscoverySettings, discover
    from dtwin.io.readers import read_record

    res = discover(read_record(IND / "planet-fault.csv"), independent_calibrated_spec,
                   settings=DiscoverySettings())
    assert [s.group for s in res.steps] == ["planet_fault"], [s.named for s in res.steps]
    low = [r for r in res.unexplained if r.frequency < res.scored_from]
    assert any(abs(r.frequency - res.kinematics.f_carrier) < 0.2 for r in low), low
    assert res.final_gap.total < 0.5 * res.initial_gap.total


@pytest.mark.slow
def test_healthy_record_adds_nothing_slow(independent_calibrated_spec):
    res = _discover("baseline-2", independent_calibrated_spec, quick=False)
    assert res.steps == [], [s.named for s in res.steps]
    # the reported held-out gap is calibration's (family-wise): ≤ 3 dB on a healthy record
    assert res.final_gap.total <= 3.0, res.final_gap.total


def test_healthy_record_adds_nothing(independent_calibrated_spec):
    """CI form of the healthy-record claim: baseline-2, which the calibration never saw, gets
    nothing added and a held-out gap (as reported, calibration's definition) ≤ 3 dB."""
    res = _discover("baseline-2", independent_calibrated_spec)
    assert res.steps == [], [s.named for s in res.steps]
    assert res.final_gap.total <= 3.0, res.final_gap.total


def test_reported_gap_is_calibrations(independent_calibrated_spec):
    """Discovery reports the held-out gap as calibration does (:func:`dtwin.identify.gap.gap`'s
    family-wise threshold, bins that noise alone reaches with probability 1 %), while its
    decisions compare the gaps over its line threshold (12 dB): on the load-fluctuation record
    each step's ``heldout_before`` is the base twin's reported gap and the last step's
    ``heldout_after`` the final one's. The reported set holds fewer bins (no
    noise-only ones); on this record the effect closes both."""
    res = _discover("load-fluct", independent_calibrated_spec)
    step = res.steps[0]
    assert step.heldout_before == res.initial_gap
    assert step.heldout_after.total == pytest.approx(res.final_gap.total)
    # the two bin sets differ: the search's counts the bins 12 dB over the floor
    assert step.gap_before.counts["all"] > res.initial_gap.counts["all"]
    assert step.gap_confirmed.total < step.gap_before.total
    assert step.heldout_after.total < step.heldout_before.total



def test_planet_fault_comb_lies_beside_k_fp_in_record_and_twin(independent_calibrated_spec):
    """The planet-fault record (as corrected: its simulator's sensor once used the healthy
    ring-mesh stiffness while its dynamics used the faulted one, which put a comb on k fp) and
    the twin calibrated on baseline-1 with a pitted tooth on planet 0 (both flanks, severity
    0.05: about the record's 30 % peak loss) agree on where the planet fault's low comb lies:
    on the carrier sidebands k fp ± fc, with k fp itself (exact multiples of the planet's fault
    frequency fm/Zp) near the noise floor. The planets' ring-mesh forces sum to the ring's
    reaction to the load, so a planet's fault moves load between the planets (seen through the
    turning window, ± fc) and leaves the sum, which the window's mean sees at k fp, unchanged
    (``tests/test_dynamics.py::test_planet_fault_low_comb_lies_beside_k_fp_not_on_it``). In the
    record the larger sideband stands 11–15 dB over the floor at odd k and 27–29 dB at even k, k fp
    within 10 dB of the floor."""
    import numpy as np

    from dtwin.identify.lines import Kinematics
    from dtwin.io.readers import read_record
    from dtwin.model.faults import Pitting
    from dtwin.model.parts.local_fault import LocalFault
    from dtwin.signal.spectrum import amplitude_spectrum
    from dtwin.simulation.simulate import simulate
    from dtwin.spec import load_spec
    from dtwin.spec.build import build_twin, daq_from_spec

    spec = load_spec(independent_calibrated_spec)
    kin = Kinematics.from_spec(spec)
    fc, fp = kin.f_carrier, kin.f_planet_fault

    def levels(f, a, k):
        """(k fp, the larger of k fp ± fc) in dB, each the largest bin within ±1 bin."""
        def at(x):
            i = int(round(x / (f[1] - f[0])))
            return 20 * np.log10(a[i - 1:i + 2].max())
        return at(k * fp), max(at(k * fp - fc), at(k * fp + fc))

    x = np.asarray(read_record(IND / "planet-fault.csv").channel(0), float)
    f, a = amplitude_spectrum(x - x.mean(), 5000.0, "hann")
    f, a = np.asarray(f), np.asarray(a)
    tw = build_twin(spec, kind="torsional", extra_parts=tuple(
        LocalFault(Pitting(0.05, location="planet", flank=fl)) for fl in ("sun", "ring")))
    res = simulate(tw, duration=4.0, f_sun=kin.f_sun, discard=0.2,
                   daq=daq_from_spec(spec, sample_rate=5000.0, snr_db=None))
    ft, at = amplitude_spectrum(np.asarray(res.signal), 5000.0, "hann", remove_mean=True)
    ft, at = np.asarray(ft), np.asarray(at)
    floor = 20 * np.log10(np.median(a[(f > 5.0) & (f < 300.0)]))
    for k in range(2, 9):  # k = 1 lies 1.85 Hz from the planet-pass line 3 fc
        on, beside = levels(f, a, k)
        assert on <= beside - 3.0 and on <= floor + 10.0, ("record", k, on, beside, floor)
        assert beside >= floor + 10.0, ("record", k, beside, floor)
        on_t, beside_t = levels(ft, at, k)
        assert on_t <= beside_t - 40.0, ("twin", k, on_t, beside_t)
