"""Discovery specialises its candidates again after a step (docs/discovery.md §4): on a
gearbox the calibrated twin did not simulate — records of a four-planet, sequentially phased
gearbox made by the translational twin, discovery with the torsional twin calibrated on a
healthy record of it — the sun fault's comb stands 18–26 dB above the twin around 1.5 kHz
once the fault is in the model, lifted by modes the torsional twin lacks. Only the current
model's residual shows it; a housing resonance located there is offered and added in the next
step, and the comb lines in its band leave the residual.

Every test here is a slow form (``make test-all``): the one claim CI would check, the
resonance kept in the second step, is an expected failure since the DAQ's pass band became flat
to 0.45 fs (RESONANCE_NOT_KEPT), and its fixture (a calibration and two 4 s translational
records) costs about 8 minutes of a 2-core CI run.
"""

import pytest
from _gearboxes import SEQUENTIAL

from dtwin.model.faults import parse_fault
from dtwin.simulation.simulate import simulate
from dtwin.spec import load_spec
from dtwin.spec.build import build_twin, daq_from_spec

QUICK = dict(max_steps=2, max_refit=1, n_boot=200)


@pytest.fixture(scope="module")
def sequential(tmp_path_factory):
    """(calibrated spec path, faulty record): the torsional twin calibrated on a healthy
    translational record; the faulty record has a sun missing tooth, severity 0.5."""
    from dtwin.identify.calibrate import calibrate

    spec = load_spec(SEQUENTIAL)

    def record(faults, seed):
        twin = build_twin(spec, kind="translational", f_sun=25.0,
                          faults=tuple(parse_fault(f) for f in faults))
        return simulate(twin, duration=4.0, f_sun=25.0, discard=0.5,
                        daq=daq_from_spec(spec, snr_db=25.0), seed=seed).to_record()

    cal = calibrate([record((), 1)], spec, kind="torsional")
    path = tmp_path_factory.mktemp("sequential") / "calibrated.toml"
    cal.write_spec(path)
    return path, record(("sun:missing_tooth:0.5",), 2)


def _discover(sequential, **kw):
    from dtwin.identify.discover import DiscoverySettings, discover

    path, rec = sequential
    return discover(rec, path, settings=DiscoverySettings(**kw))


def _band(res, k):
    step = res.steps[k]
    name = step.parameters[0]["name"]
    assert name == "housing_resonance_gain", step.parameters
    f_res = float(step.summary.split(" at ")[1].split(" Hz")[0])
    zeta = float(step.summary.split("damping ratio ")[1])
    return f_res * (1 - 3 * zeta), f_res * (1 + 3 * zeta)


def _comb_lines(lines, lo, hi):
    return [r for r in lines if r.side == "measured" and lo <= r.frequency <= hi
            and "fs/4" in r.text]


#: Since the DAQ's pass band is flat to 0.45 fs (the old filter was 6 dB down at 0.40 fs and
#: 20 dB at 0.45 fs, in the record and in the twin alike), the translational record's lines
#: above 2 kHz stand in the residual too, and the resonance is located at 2028.5 Hz (damping
#: ratio 0.1) rather than around 1.5 kHz: the linearised refit lowers the gap 9.86 → 9.39 dB but
#: the twin simulated in full does not (9.86 → 9.92 dB), and discovery declines it, as it must.
RESONANCE_NOT_KEPT = ("one resonance located between the translational modes near 1.5 and 2 kHz "
                      "is not kept once simulated in full: {}")


@pytest.mark.slow
def test_a_resonance_lifting_the_added_faults_comb_is_offered_next(sequential):
    res = _discover(sequential, **QUICK)
    assert [s.effect for s in res.steps][:1] == ["sun_local_fault"], res.stop_reason
    assert res.respecialised == [2]
    if len(res.steps) == 1:
        # offered next, first by score, refitted, and declined only by the full simulation
        first = min(res.last_candidates, key=lambda c: c.score_rank)
        assert first.name == "housing_resonance", [(c.name, c.score_rank)
                                                    for c in res.last_candidates]
        assert first.rejected and "simulated in full" in first.rejected, first.rejected
        pytest.xfail(RESONANCE_NOT_KEPT.format(first.rejected))
    assert [s.effect for s in res.steps] == ["sun_local_fault", "housing_resonance"], \
        [(s.named, s.gap_confirmed.total) for s in res.steps]
    assert res.groups == ["sun_rotation", "housing_resonance"]
    assert res.respecialised == [2]
    lo, hi = _band(res, 1)
    # the comb in the resonance's band: in the residual after the fault, gone after the mode
    before = _comb_lines(res.residuals[1], lo, hi)
    after = _comb_lines(res.residuals[2], lo, hi)
    assert len(before) >= 8 and len(after) <= len(before) // 4, (len(before), len(after))
    s = res.steps[1]
    assert s.gap_confirmed.total < s.gap_before.total - 1.0, (s.gap_before.total,
                                                             s.gap_confirmed.total)


@pytest.mark.slow
def test_specialising_again_closes_more_of_the_gap_slow(sequential):
    """The default search against the one that specialises its candidates once."""
    once = _discover(sequential, respecialise=False)
    again = _discover(sequential)
    assert once.respecialised == [] and "housing_resonance" not in once.named
    assert again.steps[0].effect == once.steps[0].effect == "sun_local_fault"
    assert "housing_resonance" in again.named
    assert again.final_gap.total < once.final_gap.total - 0.5, (once.final_gap.total,
                                                                again.final_gap.total)
    # every step kept lowers the gap of the twin simulated in full, not only the linearised one
    for res in (once, again):
        for st in res.steps:
            assert st.gap_confirmed.total < st.gap_before.total, (st.named, st.gap_before.total,
                                                                  st.gap_confirmed.total)
    k = again.named.index("housing_resonance")
    lo, hi = _band(again, k)
    left_once = _comb_lines(once.unexplained, lo, hi)
    left_again = _comb_lines(again.unexplained, lo, hi)
    assert len(left_again) <= len(left_once) // 4, (len(left_once), len(left_again))


@pytest.mark.slow
def test_a_rebuild_that_fails_leaves_the_current_model_slow(sequential, monkeypatch):
    """The model about the current twin cannot be simulated (injected): the search goes on
    with the candidates it had, as without re-specialisation, and says why."""
    import importlib

    from dtwin.errors import FitError

    # the modules, not the function `discover` that the package exports under that name;
    # the base model and the rebuild are both built in `specialise`
    loop = importlib.import_module("dtwin.identify.discover.loop")
    specialise = importlib.import_module("dtwin.identify.discover.specialise")

    built = []

    def failing(*args, **kw):
        built.append(args[0])
        if args[0] is not built[0]:  # a model about another twin than the base: the rebuild
            raise FitError("injected")
        return extended_model(*args, **kw)

    extended_model = specialise.extended_model
    monkeypatch.setattr(specialise, "extended_model", failing)
    lines = []
    res = loop.discover(sequential[1], sequential[0],
                        settings=loop.DiscoverySettings(**QUICK), log=lines.append)
    assert built[-1] is not built[0] and res.respecialised == []
    assert any("failed (FitError: injected); the candidates stay as they were" in t
               for t in lines), lines
    assert res.steps and res.steps[0].effect == "sun_local_fault"
    assert "housing_resonance" not in [s.effect for s in res.steps]
