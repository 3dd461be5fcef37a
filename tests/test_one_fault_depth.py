"""One path to a fault depth (issue "One fault depth", item 1): ``dtwin severity``, ``dtwin
identify --free sun_fault``, ``dtwin fleet identify --free sun_fault`` and ``dtwin discover``'s
depth of the sun fault it names fit the same problem on the same record and spec — the same
twin, the same ends of the calibration's excitation/response split, the same bands — and give
the same number, to the solver's tolerance.

On a record of the independent family (``../shared/independent/sun-fault-0.60.csv``: another
simulator, a sun tooth fault whose peak stiffness loss is 0.36 in its ``truth.json``) with the
spec calibrated on that gearbox's baseline-1 (``tests/_independent.py``, once per run). The
commands run in this process through the command line's own entry, as a user types them;
discovery's search is replaced by a result naming the sun fault (the search itself is checked
on family records in ``tests/test_family.py``), so what is checked here is that its depth is
severity's. The number is also checked against the truth: the reported peak loss's interval
holds 0.36.
"""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest
from _bench import run_cli
from _independent import IND, needs_independent

RECORD = IND / "sun-fault-0.60.csv"


def _truth_peak() -> float:
    effects = json.loads((IND / "truth.json").read_text())["records"]["sun-fault-0.60"]["effects"]
    return float(effects[0]["peak_stiffness_loss"])


def _discovery_naming_the_sun_fault():
    """A discovery result with one step that added the sun's local tooth fault (as the search
    names it on this record: docs/discovery.md), written by hand."""
    from dtwin.identify.discover.results import DiscoveryResult, Step
    from dtwin.identify.discover.settings import DiscoverySettings
    from dtwin.identify.gap import GapResult
    from dtwin.model.kinematics import Kinematics

    gap = GapResult(10.0, {"all": 10.0}, {"all": 10})
    kin = Kinematics.from_gears(21, 31, 84, 3, 29.7)
    main = dict(name="pitting severity", unit="1", value=0.5, sigma=0.05,
                interval=[0.4, 0.6], interval_kind="profile", typical_range=[0.05, 0.6],
                typical_note="")
    step = Step(1, "sun_local_fault", "sun_rotation", "sun_local_fault", [], [], [], main,
                1e-4, 0.01, gap, gap, gap, [])
    z = np.zeros(4)
    return DiscoveryResult(kin, 29.7, 5000.0, DiscoverySettings(), [step], gap, gap, [], [],
                           0.0, "stand-in", [], z, z, [z, z], [[], []])


#: estimate_severity's options that decide the problem and its solution (defaults filled in)
DECIDING = ("kind", "f_sun", "channel", "splits", "low_band", "ramps", "flanks", "jackknife",
            "initial_severity", "solver", "max_steps", "tol", "jac", "starts", "refine",
            "spread", "seed", "sigma_tol", "uncertainty", "scan", "confounding", "features",
            "initial", "runup")


def _deciding(kwargs: dict, estimate_severity) -> dict:
    """The options of one `estimate_severity` call that decide its problem and solution, with
    its own and fit's defaults filled in."""
    import dataclasses
    import inspect

    from dtwin.identify.fit import fit
    from dtwin.identify.fit_settings import FitSettings

    # fit's settings (FitSettings' defaults), then fit's and estimate_severity's own keywords
    out = {f.name: f.default for f in dataclasses.fields(FitSettings)}
    for f in (fit, estimate_severity):
        for n, p in inspect.signature(f).parameters.items():
            if p.default is not inspect.Parameter.empty:
                out[n] = p.default
    out.update(kwargs)
    return {k: out.get(k) for k in DECIDING}


def _spec_text(spec) -> str:
    """A spec's content (path, mapping or `Spec`) as JSON, without where it was read from."""
    from dtwin.spec import Spec, load_spec, spec_to_dict

    data = spec_to_dict(spec if isinstance(spec, Spec) else load_spec(spec))
    data.pop("source", None)
    return json.dumps(data, sort_keys=True, default=str)


def _four_commands(spec: str, tmp_path, monkeypatch):
    """``dtwin severity``, ``identify --free sun_fault``, ``fleet identify --free sun_fault``
    (``--grid hz``) and ``discover`` (its search replaced by a result naming the sun fault) on
    the record with `spec`, each as a user types it: severity's JSON, identify's, the fleet's
    result entry and discover's."""
    code, sev, err = run_cli("severity", str(RECORD), "--spec", spec, "--location", "sun",
                             "--json")
    assert code == 0, err
    code, ident, err = run_cli("identify", str(RECORD), "--spec", spec, "--free", "sun_fault",
                               "--json")
    assert code == 0, err
    code, _, err = run_cli("fleet", "identify", str(RECORD), "--spec", spec, "--free",
                           "sun_fault", "--grid", "hz", "--engine", "local", "--no-progress",
                           "--out", str(tmp_path / "fleet"))
    assert code == 0, err
    (entry,) = [json.loads(p.read_text()) for p in (tmp_path / "fleet" / "records").glob(
        "*.json") if not p.name.endswith(".discover.json")]
    disc = importlib.import_module("dtwin.identify.discover")
    monkeypatch.setattr(disc, "discover", lambda *a, **k: _discovery_naming_the_sun_fault())
    code, found, err = run_cli("discover", str(RECORD), "--spec", spec, "--json")
    assert code == 0, err
    return sev, ident, entry, found


@needs_independent
def test_each_command_fits_the_depth_severity_fits(independent_calibrated_spec, tmp_path,
                                                   monkeypatch):
    """`dtwin severity` for real; identify, fleet and discover with estimate_severity watched
    (module docstring): the same call, and its estimate reported as it is."""
    sev_module = importlib.import_module("dtwin.identify.severity")

    spec = str(independent_calibrated_spec)
    real = sev_module.estimate_severity
    calls = []

    def watched(record, spec_or_twin, location="sun", **kwargs):
        calls.append((np.asarray(record.data).copy(), float(record.sample_rate),
                      _spec_text(spec_or_twin), location, _deciding(kwargs, real)))
        if len(calls) == 1:
            watched.estimate = real(record, spec_or_twin, location, **kwargs)
        return watched.estimate

    monkeypatch.setattr(sev_module, "estimate_severity", watched)
    # the modules, not the functions dtwin.identify exports under their names
    for where in ("dtwin.identify.fleet.tasks", "dtwin.identify.discover.depth"):
        monkeypatch.setattr(importlib.import_module(where), "estimate_severity", watched)
    sev, ident, entry, found = _four_commands(spec, tmp_path, monkeypatch)

    assert len(calls) == 4, [c[3] for c in calls]
    data, fs, spec_seen, loc, options = calls[0]
    assert loc == "sun" and options["kind"] is None  # severity's twin, whatever the spec's
    for k, (d, f, sp, lc, opt) in enumerate(calls[1:], start=1):
        assert f == fs and d.shape == data.shape and np.array_equal(d, data), k
        assert sp == spec_seen and lc == loc, k
        assert opt == options, (k, {n: (opt[n], options[n]) for n in opt
                                    if opt[n] != options[n]})
    est = watched.estimate
    for other in (ident["severity"], entry["severity"], found["steps"][0]["depth"], sev):
        assert other["severity"] == est.severity
        assert other["peak_stiffness_loss"] == est.peak_loss
        assert other["status"] == est.status
    assert ident["values"]["sun_fault"] == entry["values"]["sun_fault"] == est.severity
    assert entry["intervals_95"]["sun_fault"] == list(est.interval)
    # the number is the record's: the interval of the peak loss holds the truth
    lo, hi = est.peak_interval
    assert lo <= _truth_peak() <= hi, (lo, est.peak_loss, hi)


@pytest.mark.slow
@needs_independent
def test_severity_identify_fleet_and_discover_give_one_depth(independent_calibrated_spec,
                                                             tmp_path, monkeypatch):
    spec = str(independent_calibrated_spec)
    sev, ident, entry, found = _four_commands(spec, tmp_path, monkeypatch)
    depth = found["steps"][0]["depth"]
    print(sev["severity"], sev["peak_stiffness_loss"], sev["status"], sep="\n")

    # one problem: the same twin, the same end of the calibration's split, the same bands
    for other in (ident["severity"], entry["severity"], depth):
        assert other["twin_kind"] == sev["twin_kind"] == "translational"
        assert other["excitation"] == sev["excitation"]
        assert other["low_band"] == sev["low_band"] is True
    assert ident["model"] == "translational"
    # the same number: identify and discover run severity's fit as it is; the fleet's solver
    # tolerance (--tol 1e-4 on θ, the logit of the severity) allows a few such steps
    for other in (ident["severity"], depth):
        assert other["severity"] == pytest.approx(sev["severity"], rel=1e-6)
        assert other["peak_stiffness_loss"] == pytest.approx(sev["peak_stiffness_loss"],
                                                             rel=1e-6)
        assert other["status"] == sev["status"]
    assert ident["values"]["sun_fault"] == pytest.approx(sev["severity"], rel=1e-6)
    s = sev["severity"]
    assert abs(entry["values"]["sun_fault"] - s) < 10 * 1e-4 * s * (1 - s) + 1e-9
    assert entry["intervals_95"]["sun_fault"] == pytest.approx(sev["interval_95"], rel=1e-2)
    # and the number is the record's: the interval of the peak loss holds the truth
    lo, hi = sev["peak_stiffness_loss_interval_95"]
    assert lo <= _truth_peak() <= hi, (lo, sev["peak_stiffness_loss"], hi)
