"""dtwin.identify.fleet / dtwin.identify.trends / `dtwin fleet` (issue 10 "Tests that must pass").

A fleet of three short synthetic records (torsional twin, 0.35 s at 5 kHz, 30 dB SNR, sun-fault
severity 0.35 / 0.5 / 0.65 at input speeds 29.5 / 30.0 / 30.6 Hz, machine and timestamp in the
record metadata) plus one corrupt file. One free parameter (sun_fault, start 0.3), the speed
estimated from each record, residuals in the order domain (the fleet's default), so each fit
converges in a few LM steps.

- sequential path (no Ray): a task raising for one record (injected) and a corrupt record are
  reported per record while the others complete; an interrupted run keeps its finished results;
  a re-run fits only the missing records;
- Ray (local cluster of 2 workers; Ray is in the ``test`` extra): a worker killed mid-run
  (injected ``os._exit``) is retried, the results equal the sequential ones, and no Ray process
  outlives the test;
- batched vs single fits: the three records, at three speeds, in ONE batched fit_batch call
  (order domain: shapes independent of the speed), converged, equal to the single fits to the
  solver tolerance;
- table (Parquet, or CSV without pyarrow), never overwritten without --force;
- trend flags on synthetic rising / flat / slowly rising severity series, figures, CLI.
"""

import dataclasses
import json
import os

import numpy as np
import pytest

from dtwin.io.readers import write_record
from dtwin.model.faults import MissingTooth
from dtwin.simulation.simulate import DAQ, simulate
from dtwin.spec import preset
from dtwin.spec.build import build_twin

SEVERITIES = (0.35, 0.5, 0.65)
SPEEDS = (29.5, 30.0, 30.6)  # Hz: one batch in the order domain
DURATION = 0.35  # s: just over 2 / f_carrier (6.1 Hz at 29.5 Hz), the shortest the fit accepts
SNR_DB = 30.0
TOL = 1e-3  # LM rtol (atol = TOL/100): above the residuals' ODE-tolerance jitter (~1e-6)


def _settings(**kw):
    from dtwin.identify.fleet import FleetSettings

    # the records are the torsional twin's: fitted with it (a tooth fault's default twin is
    # severity's, translational: dtwin.identify.fleet, "A tooth fault's depth")
    base = dict(free=("sun_fault",), kind="torsional", initial={"sun_fault": 0.3},
                max_steps=40, tol=TOL, max_retries=1)
    base.update(kw)
    return FleetSettings(**base)


@pytest.fixture(scope="module")
def spec():
    return preset("paper-sim")


@pytest.fixture(scope="module")
def fleet_records(tmp_path_factory, spec):
    root = tmp_path_factory.mktemp("fleet") / "records"
    for i, (sev, f) in enumerate(zip(SEVERITIES, SPEEDS, strict=True)):
        tw = build_twin(spec, kind="torsional", faults=(MissingTooth(sev, location="sun"),),
                        f_sun=f)
        rec = simulate(tw, duration=DURATION, f_sun=f, daq=DAQ(sample_rate=5000.0,
                       snr_db=SNR_DB), discard=0.05, seed=i).to_record()
        rec = dataclasses.replace(rec, metadata={**rec.metadata, "machine": f"m{i % 2}",
                                                 "timestamp": f"2026-01-0{i + 1}T00:00:00Z"})
        write_record(rec, root / f"m{i}" / f"rec{i}.dtwin.h5")
    bad = root / "z_bad" / "rec_bad.dtwin.h5"
    bad.parent.mkdir(parents=True)
    bad.write_bytes(b"this is not an HDF5 file")
    return root


@pytest.fixture(scope="module")
def sequential(fleet_records, spec, tmp_path_factory):
    """Run 1: rec1's task raises (injected, every attempt) and the run is interrupted after the
    second entry; run 2: no injection, runs to the end."""
    from dtwin.identify.fleet import run_fleet

    out = tmp_path_factory.mktemp("fleet-seq") / "results"
    pattern = str(fleet_records / "**" / "*.dtwin.h5")
    seen = []

    def stop_after_two(entry):
        seen.append(entry)
        if len(seen) == 2:
            raise KeyboardInterrupt

    os.environ["DTWIN_FLEET_FAIL"] = "rec1"
    try:
        with pytest.raises(KeyboardInterrupt):
            run_fleet([pattern], spec, out, _settings(), engine="local", progress=False,
                      on_result=stop_after_two)
    finally:
        del os.environ["DTWIN_FLEET_FAIL"]
    first = {p.name: p.read_bytes() for p in (out / "records").glob("*.json")}
    failed_first = {p.name: json.loads(p.read_text()) for p in (out / "failed").glob("*.json")}
    run2 = run_fleet([pattern], spec, out, _settings(), engine="local", progress=False)
    return dict(out=out, pattern=pattern, seen=seen, first=first, failed_first=failed_first,
                run2=run2)


def _values(out):
    from dtwin.identify.fleet import load_results

    return {r["record"].split("/")[-1]: r for r in load_results(out) if r["status"] == "ok"}


def test_failure_reported_per_record_and_interrupt_keeps_results(sequential):
    seen = sequential["seen"]
    assert [e["status"] for e in seen] == ["ok", "failed"]
    assert seen[0]["record"].endswith("rec0.dtwin.h5")
    assert seen[1]["record"].endswith("rec1.dtwin.h5")
    assert seen[1]["error_type"] == "RuntimeError" and "injected" in seen[1]["error"]
    assert seen[1]["attempts"] == 2  # max_retries=1: tried twice, then reported
    # the finished result was on disk when the run was interrupted, complete and readable
    (name,) = sequential["first"]
    d = json.loads(sequential["first"][name])
    assert d["status"] == "ok" and d["machine"] == "m0" and "sun_fault" in d["intervals_95"]
    assert list(sequential["failed_first"].values())[0]["stage"] == "task"


def test_rerun_finishes_only_the_missing(sequential):
    run2 = sequential["run2"]
    assert run2.records == 4
    assert run2.skipped == 1  # rec0 was done
    assert run2.fitted == 2  # rec1 (failed before) and rec2 (never reached)
    assert run2.failed == 1  # the corrupt file, reported (read stage, not retried)
    (bad,) = run2.failures
    assert bad["stage"] == "read" and bad["error_type"] == "UnreadableFileError"
    assert bad["record"].endswith("rec_bad.dtwin.h5")
    out = sequential["out"]
    # rec0's file untouched by the re-run; rec1's failure entry removed once it succeeded
    for name, data in sequential["first"].items():
        assert (out / "records" / name).read_bytes() == data
    assert not any(p.name.startswith("rec1") for p in (out / "failed").glob("*.json"))
    vals = _values(out)
    assert set(vals) == {"rec0.dtwin.h5", "rec1.dtwin.h5", "rec2.dtwin.h5"}
    est = [vals[f"rec{i}.dtwin.h5"]["values"]["sun_fault"] for i in range(len(SEVERITIES))]
    # the fleet keeps what each fit says; sanity only (fit accuracy is test_identify_fit's):
    # estimates follow the true severities, intervals bracket the estimates, gaps are finite
    assert np.all(np.diff(est) > 0), est
    for i in range(len(SEVERITIES)):
        r = vals[f"rec{i}.dtwin.h5"]
        assert abs(r["f_sun"] - SPEEDS[i]) < 0.01, (r["f_sun"], SPEEDS[i])  # operating point
        assert r["converged"], r["message"]
        lo, hi = r["intervals_95"]["sun_fault"]
        assert lo <= r["values"]["sun_fault"] <= hi
        assert np.isfinite(r["gap_db"]) and r["gap_db"] >= 0.0
        assert r["machine"] == f"m{i % 2}" and r["timestamp"].startswith(f"2026-01-0{i + 1}")
    runs = sorted((out / "runs").glob("*.json"))
    statuses = [json.loads(p.read_text())["status"] for p in runs]
    assert statuses[:2] == ["interrupted", "finished"], statuses


def _ray_processes():
    """This process's descendants that Ray started (raylet, gcs_server, workers, …)."""
    import psutil

    out = []
    for p in psutil.Process().children(recursive=True):
        try:
            if "ray" in " ".join(p.cmdline()).lower():
                out.append(p)
        except psutil.Error:
            pass
    return out


@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")  # ray.init starts its daemons
def test_ray_cluster_matches_sequential(sequential, spec, tmp_path):
    ray = pytest.importorskip("ray", reason="Ray not installed: pip install 'dtwin[fleet]' "
                              "(ray>=2.9, pyarrow>=15) to run the cluster test")
    import psutil

    from dtwin.identify.fleet import run_fleet

    assert not ray.is_initialized()
    # two workers on the CI's two cores; a small object store (the tasks pass only JSON)
    ray.init(num_cpus=2, object_store_memory=100 * 1024**2, include_dashboard=False,
             log_to_driver=False, configure_logging=False)
    try:
        os.environ["DTWIN_FLEET_FAIL"] = "rec2:exit@1"  # rec2's worker dies on the 1st attempt
        try:
            run = run_fleet([sequential["pattern"]], spec, tmp_path / "ray", _settings(),
                            engine="ray", progress=False)
        finally:
            del os.environ["DTWIN_FLEET_FAIL"]
    finally:
        ray.shutdown()
    # no leaked Ray process: the daemons and workers exit with the shutdown
    _, alive = psutil.wait_procs(_ray_processes(), timeout=30)
    assert not alive, [p.cmdline()[:2] for p in alive]
    assert run.engine == "ray" and run.fitted == 3 and run.failed == 1
    attempts = list((tmp_path / "ray" / ".attempts").glob("rec2-*.attempts"))
    assert len(attempts) == 1 and attempts[0].stat().st_size == 2  # killed once, retried
    seq, par = _values(sequential["out"]), _values(tmp_path / "ray")
    assert set(par) == set(seq)
    for name, r in seq.items():
        assert par[name]["engine"] == "ray"
        np.testing.assert_allclose(par[name]["values"]["sun_fault"], r["values"]["sun_fault"],
                                   rtol=1e-8)
        np.testing.assert_allclose(par[name]["intervals_95"]["sun_fault"],
                                   r["intervals_95"]["sun_fault"], rtol=1e-6)


def test_order_domain_shapes_do_not_depend_on_speed(fleet_records, spec):
    """The fleet's residuals (order domain) give the three records, at 29.5, 30.0 and 30.6 Hz,
    one problem structure (statics and shapes), so they stack into one vmap; on DFT bins
    (``grid="hz"``) the structures differ. No simulation."""
    from dtwin.errors import FitError
    from dtwin.identify.fit import make_problem, stack_problems
    from dtwin.identify.fleet import _structure
    from dtwin.io.readers import read_record
    from dtwin.spec import spec_to_dict

    recs = [read_record(fleet_records / f"m{i}" / f"rec{i}.dtwin.h5") for i in range(3)]

    def problems(settings):
        kw = settings.resolved(spec_to_dict(spec)).problem_kwargs()
        return [make_problem(r, spec, ["sun_fault"], **kw)[0] for r in recs]

    orders = problems(_settings())
    assert orders[0].observations[0].order_domain
    assert orders[0].observations[0].f_ref == 31.5  # 1.05 × the spec's 30 Hz
    speeds = [float(p.observations[0].speed[0]) for p in orders]
    np.testing.assert_allclose(speeds, SPEEDS, atol=0.01)
    assert all(_structure(p) == _structure(orders[0]) for p in orders[1:])
    stacked = stack_problems(orders)
    assert stacked.observations[0].meas.shape[0] == 3
    # the same orders at every speed: the points are the grid's orders × the record's speed
    o = [np.asarray(p.observations[0].freqs) / s for p, s in zip(orders, speeds, strict=True)]
    np.testing.assert_allclose(o[1], o[0], rtol=1e-12)
    np.testing.assert_allclose(o[2], o[0], rtol=1e-12)
    hz = problems(_settings(grid="hz"))
    assert _structure(hz[0]) != _structure(hz[2])
    with pytest.raises(FitError, match="share length, rate"):
        stack_problems(hz)


def test_batched_fit_agrees_with_single_fits(sequential, spec, tmp_path, monkeypatch):
    """The three records (29.5, 30.0, 30.6 Hz) in one task: ONE batched fit_batch call (order
    domain: one structure for every speed); every fit converged, and the values equal the
    single fits of the sequential run (dtwin.identify.fit.fit, same start θ = 0, same solver) to the
    solver tolerance."""
    import importlib

    from dtwin.identify.fleet import run_fleet

    fit_module = importlib.import_module("dtwin.identify.fit")  # dtwin.identify.fit is also the function

    calls = []
    fit_batch = fit_module.fit_batch

    def counting_fit_batch(records, *a, **k):
        calls.append(len(records))
        return fit_batch(records, *a, **k)

    monkeypatch.setattr(fit_module, "fit_batch", counting_fit_batch)
    settings = _settings(batch_size=3)
    run = run_fleet([sequential["pattern"]], spec, tmp_path / "batch", settings, engine="local",
                    progress=False, table=False)
    assert run.fitted == 3 and calls == [3]  # one batched call for the three speeds
    seq, bat = _values(sequential["out"]), _values(tmp_path / "batch")
    assert set(bat) == set(seq)
    speeds = [r["f_sun"] for r in bat.values()]
    assert max(speeds) - min(speeds) > 1.0, speeds
    for name, r in seq.items():
        b = bat[name]
        assert b["batched_with"] == 3
        assert r["converged"] and b["converged"], (name, r["message"], b["message"])
        assert b["f_sun"] == r["f_sun"]  # same operating point
        th_s, th_b = r["fit"]["theta"][0], b["fit"]["theta"][0]
        # LM stops when the step is below atol + rtol |θ| (rtol = tol, atol = tol/100): two
        # converged runs of the same problem agree to a few such steps
        assert abs(th_b - th_s) < 10 * settings.tol, (name, th_s, th_b)
        assert abs(b["values"]["sun_fault"] - r["values"]["sun_fault"]) < 10 * settings.tol


def test_table_and_cli(sequential, capsys):
    from dtwin.cli import main
    from dtwin.identify.fleet import TABLE_NAME

    out = sequential["out"]
    first = sequential["run2"].table
    assert first is not None and first.exists()
    main(["fleet", "table", str(out)])
    tables = sorted(out.glob("table*"))
    assert len(tables) == 2  # rebuilt into a new file, the old one kept
    main(["fleet", "table", str(out), "--force"])
    assert len(sorted(out.glob("table*"))) == 2
    capsys.readouterr()
    if first.name == TABLE_NAME:
        pq = pytest.importorskip("pyarrow.parquet")
        tbl = pq.read_table(first).to_pylist()
    else:  # without pyarrow: CSV
        import csv

        tbl = list(csv.DictReader(first.read_text().splitlines()))
    assert len(tbl) == 4
    ok = [r for r in tbl if r["status"] == "ok"]
    assert {r["machine"] for r in ok} == {"m0", "m1"}
    for r in ok:
        assert {"sun_fault", "sun_fault_lo95", "sun_fault_hi95", "gap_db", "timestamp",
                "effects"} <= set(r)
    main(["fleet", "table", str(out), "--json"])
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert sum(r["status"] == "failed" for r in rows) == 1


def test_without_ray_runs_locally_and_skips_done(sequential, spec, monkeypatch):
    import dtwin.identify.fleet as fleet
    from dtwin.identify.fleet import ray_engine

    monkeypatch.setattr(ray_engine, "ray_available", lambda: False)  # where run_fleet asks
    run = fleet.run_fleet([sequential["pattern"]], spec, sequential["out"], _settings(),
                          engine="auto", progress=False, table=False)
    assert run.engine == "local" and run.skipped == 3 and run.fitted == 0
    assert any("Ray is not installed" in n for n in run.notes)


def test_other_settings_refused(sequential, spec):
    from dtwin.errors import OutputExistsError
    from dtwin.identify.fleet import run_fleet

    with pytest.raises(OutputExistsError, match="other fit settings"):
        run_fleet([sequential["pattern"]], spec, sequential["out"], _settings(max_steps=7),
                  engine="local", progress=False)


# ------------------------------------------------------------------------------ identity
def test_manifest_overrides_metadata_and_folder(tmp_path, fleet_records):
    from dtwin.identify.fleet import _make_job, read_fleet_manifest

    rec0 = fleet_records / "m0" / "rec0.dtwin.h5"
    csv = tmp_path / "fleet.csv"
    csv.write_text(f"path,machine,timestamp\n{rec0},turbine-7,2026-03-01 12:00\n")
    man = read_fleet_manifest(csv)
    job = _make_job(rec0, man)
    assert (job.machine, job.timestamp, job.identity_source) == (
        "turbine-7", "2026-03-01T12:00:00+00:00", "manifest")
    job = _make_job(rec0, None)
    assert (job.machine, job.identity_source) == ("m0", "metadata")
    assert job.timestamp == "2026-01-01T00:00:00+00:00"
    bad = fleet_records / "z_bad" / "rec_bad.dtwin.h5"
    job = _make_job(bad, None)
    assert (job.machine, job.timestamp, job.identity_source) == ("z_bad", None, "folder")
    csv.write_text("path,machine\nx,y\n")
    from dtwin.errors import RecordError

    with pytest.raises(RecordError, match="timestamp"):
        read_fleet_manifest(csv)


# ------------------------------------------------------------------------------ trends
def _series(machine, days, sev, half=0.03):
    return [{"status": "ok", "machine": machine, "record": f"{machine}/d{d}",
             "timestamp": f"2026-02-{1 + d:02d}T00:00:00+00:00", "names": ["sun_fault"],
             "values": {"sun_fault": s}, "intervals_95": {"sun_fault": [s - half, s + half]}}
            for d, s in zip(days, sev, strict=True)]


def test_trend_flags_on_synthetic_series():
    from dtwin.identify.trends import fit_trend, machine_trends

    rng = np.random.default_rng(0)
    days = list(range(7))
    rising = 0.1 + 0.08 * np.arange(7)  # 0.10 … 0.58: crosses 0.4 at day 3.75
    flat = 0.15 + 0.01 * rng.standard_normal(7)
    slow = 0.1 + 0.02 * np.arange(7)  # 0.22 at day 6, reaches 0.4 at day 15
    res = (_series("rising", days, rising) + _series("flat", days, flat)
           + _series("slow", days, slow))
    tr = machine_trends(res, {"sun_fault": (0.4, "above")}, horizon_days=30)
    f = tr["rising"].parameters["sun_fault"].flag
    assert f.state == "crossed"
    assert f.crossing_time.startswith("2026-02-04T18")  # day 3.75 after Feb 1
    assert tr["flat"].parameters["sun_fault"].flag.state == "ok"
    g = tr["slow"].parameters["sun_fault"].flag
    assert g.state == "approaching" and g.crossing_time.startswith("2026-02-16")
    assert tr["rising"].state == "crossed" and tr["flat"].flagged == []
    # the weighted line equals numpy's polyfit for equal intervals
    a, b, _ = fit_trend(days, rising, rising - 0.03, rising + 0.03)
    np.testing.assert_allclose([b, a], np.polyfit(days, rising, 1), rtol=1e-10)
    # relative thresholds: a stiffness falling 30 % is flagged below "-20%"
    k = 1e8 * (1 - 0.05 * np.arange(7))
    res_k = [{"status": "ok", "machine": "k", "record": f"d{d}",
              "timestamp": f"2026-02-{1 + d:02d}T00:00:00+00:00", "names": ["k_sun_planet"],
              "values": {"k_sun_planet": v}, "intervals_95": {"k_sun_planet": [v * .98, v * 1.02]}}
             for d, v in enumerate(k)]
    fk = machine_trends(res_k)["k"].parameters["k_sun_planet"].flag
    assert fk.state == "crossed" and fk.threshold == pytest.approx(0.8e8)


def test_trend_figures_and_cli(sequential, capsys):
    from dtwin.cli import main

    out = sequential["out"]
    main(["fleet", "trends", str(out), "--threshold", "sun_fault>0.45", "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert set(rep["machines"]) == {"m0", "m1"}
    m0 = rep["machines"]["m0"]  # rec0 (0.2) and rec2 (0.5): two records, no trend yet
    assert m0["records"][0].endswith("rec0.dtwin.h5") and len(m0["records"]) == 2
    # two records: no trend; a crossing when the last value (rec2, 0.5 simulated) lies above
    last = m0["parameters"]["sun_fault"]["values"][-1]
    assert m0["parameters"]["sun_fault"]["flag"]["state"] == ("crossed" if last > 0.45
                                                              else "too_few")
    files = set(json.loads((out / "trends" / "manifest.json").read_text())["files"])
    assert {"trends.json", "trend_m0.png", "trend_m1.png", "overview.png"} <= files
