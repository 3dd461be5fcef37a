"""``dtwin fleet``: identify many records (Ray or one after another), gather a table, trends.

    dtwin fleet identify 'records/**/*.dtwin.h5' (--spec FILE | --preset NAME) --out RESULTS
                   [--free sun_fault,...] [--model torsional|translational] [--f-sun HZ]
                   [--tacho CHANNEL[:PPR[:SHAFT]]]
                   [--ray-address ADDRESS] [--engine auto|ray|local] [--num-cpus N]
                   [--batch-size N] [--max-retries N] [--discover] [--manifest fleet.csv]
                   [--max-steps N] [--tol T] [--starts N] [--refine K] [--grid orders|hz]
                   [--order-step S] [--f-max HZ] [--splits/--no-splits]
                   [--no-progress] [--json] [--force]
    dtwin fleet table RESULTS [--csv] [--json] [--force]
    dtwin fleet trends RESULTS [--threshold 'sun_fault>0.4' ...] [--horizon DAYS]
                   [--out DIR] [--json] [--force]

``identify`` runs :func:`dtwin.identify.fleet.run_fleet`: Ray tasks (local Ray by default, an
existing cluster with ``--ray-address``; without Ray installed the records run one after
another here), a progress bar over records, per-task retries, one JSON file per record in
``RESULTS/records`` written as each task finishes, a re-run skips what is done, and the table
``RESULTS/table.parquet`` at the end (a new time-stamped file if one exists, unless
``--force``). ``table`` rebuilds the table on demand. ``trends`` writes ``trends.json``,
``trend_<machine>.png`` and ``overview.png`` (default into ``RESULTS/trends``) and prints one
line per machine with its flagged parameters. See docs/fleet.md.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import typer

from . import options as opts
from .app import app
from .logs import is_quiet, note, warn

fleet_app = typer.Typer(help="Fleet runs (many records, in batch or on a Ray cluster; the "
                        "results table; per-machine trends): identify, table, trends.")
app.add_typer(fleet_app, name="fleet")

#: Most retries of a failed task `--max-retries` accepts.
MAX_RETRIES = 10


def _echo_json(obj) -> None:
    from ..io.output import to_jsonable

    typer.echo(json.dumps(to_jsonable(obj), indent=2))


def _refuse_unusable_fleet(files, gearbox, settings) -> None:
    """Before any worker starts (a local Ray takes half a minute): the records are checked one
    after the other, as each task will check its own (read, the channel, the record's usability,
    a steady record's mesh lines against its speed), until one passes; a fleet none of whose
    records could be fitted is refused at once, naming each record's problem (issue 53: one
    truncated record took 50 s, Ray's start, to end in "1 failed"). Checking stops at the first
    usable record: the others are checked by their tasks, as before."""
    from dtwin.identify.fleet.tasks import runup_range
    from dtwin.io.readers import read_record

    from ..errors import DtwinError, RecordError
    from .logs import set_quiet

    problems = []
    quiet = is_quiet()
    set_quiet(True)  # each task warns about its own record
    try:
        for path in files:
            try:
                rec = read_record(path, **settings.record_reading())
                opts.check_channel(rec, settings.channel)
                opts.checked_record(rec, settings.channel)
                if runup_range(rec, gearbox, settings.channel) is None:
                    opts.check_speed_against_lines(rec, gearbox, settings.f_sun,
                                                   settings.channel, path)
                return
            except DtwinError as e:
                text = str(e).splitlines()[0] if str(e) else type(e).__name__
                problems.append(text if str(path) in text else f"{path}: {text}")
    finally:
        set_quiet(quiet)
    shown = "; ".join(problems[:3]) + (f"; and {len(problems) - 3} more" if len(problems) > 3
                                       else "")
    raise RecordError(f"none of the {len(problems)} record(s) can be fitted: {shown}")


@fleet_app.command("identify")
def fleet_identify(
    records: list[str] = typer.Argument(..., help="Record files or quoted glob patterns "
                                        "('records/**/*.dtwin.h5')."),
    out: Path = typer.Option(..., "--out", help="Results folder (re-used by a re-run)."),
    spec: Path | None = opts.spec_option(),
    preset: str | None = opts.preset_option(),
    free: str = typer.Option("sun_fault", "--free", help="Comma-separated registry names."),
    model: str | None = typer.Option(None, "--model", help="torsional or translational twin "
                                     "(default: the kind a calibrated spec was calibrated "
                                     "with, otherwise torsional; a tooth fault's severity is "
                                     "fitted as `dtwin severity` fits it, with its twin)."),
    f_sun: float | None = opts.f_sun_option("Input speed (Hz) of every record; "),
    tacho: str | None = opts.tacho_option(),
    ray_address: str | None = typer.Option(None, "--ray-address", help="An existing Ray "
                                           "cluster (ray://HOST:10001 or auto)."),
    engine: str = typer.Option("auto", "--engine", help="auto (Ray if installed), ray, local."),
    num_cpus: int | None = typer.Option(None, "--num-cpus", parser=opts.whole_number,
                                        help="CPUs of a local Ray (at most this machine's)."),
    batch_size: int = typer.Option(1, "--batch-size", parser=opts.whole_number,
                                   help="Records per task, fitted in one "
                                   "vmapped call when they share length and rate (order "
                                   "domain; with --grid hz also the speed to 0.1 Hz)."),
    max_retries: int = typer.Option(2, "--max-retries", parser=opts.whole_number,
                                    help="Retries of a failed task (at most "
                                    f"{MAX_RETRIES})."),
    discover: bool = typer.Option(False, "--discover", help="Also run discovery per record "
                                  "(its own tasks; costly)."),
    manifest: Path | None = typer.Option(None, "--manifest", help="Fleet manifest CSV: path, "
                                         "machine, timestamp."),
    max_steps: int = typer.Option(40, "--max-steps", parser=opts.whole_number,
                                  help="Solver steps per fit."),
    tol: float = typer.Option(1e-4, "--tol", help="Solver tolerance: rtol = atol = tol on θ and "
                              "on the residuals (RMS norm); 1e-3 converges in fewer steps on "
                              "short records (docs/fleet.md)."),

    starts: int = typer.Option(1, "--starts", parser=opts.whole_number,
                               help="Grid starts (batch size 1 only)."),
    refine: int = typer.Option(1, "--refine", parser=opts.whole_number,
                               help="Starts refined (batch size 1 only)."),
    grid: str = typer.Option("orders", "--grid", help="orders (residuals in the order domain: "
                             "records at any speed batch together) or hz (DFT bins)."),
    order_step: float | None = typer.Option(None, "--order-step", help="Step of the order "
                                            "grid (orders; default one DFT bin at --f-max)."),
    f_max: float | None = typer.Option(None, "--f-max", help="Highest input speed of the "
                                       "fleet (Hz; default 1.05 x --f-sun or the spec's)."),
    channel: str = typer.Option("0", "--channel", help="Channel name or index."),
    splits: bool | None = opts.splits_option("a fault severity is free"),
    no_progress: bool = typer.Option(False, "--no-progress", help="No progress bar."),
    json_out: bool = typer.Option(False, "--json", help="Print the run summary as JSON."),
    force: bool = typer.Option(False, "--force", help="Refit results of other settings; "
                               "overwrite the table."),
) -> None:
    """Identify every record of a fleet: Ray tasks, one result file per record, a table."""
    from dtwin.identify.fleet import FleetSettings, run_fleet
    from dtwin.identify.severity import fault_location

    from ..spec.build import twin_kind, warn_torsional_tooth_fault

    names = opts.free_names("--free", free)
    opts.choice("--model", model, ("torsional", "translational"))
    opts.input_speed_option("--f-sun", f_sun)
    reading = opts.tacho_reading(tacho)
    opts.choice("--engine", engine, ("auto", "ray", "local"))
    if num_cpus is not None:
        cpus = os.cpu_count() or 1
        opts.count("--num-cpus", num_cpus, 1, cpus, f"this machine has {cpus} CPUs, and each "
                   "Ray worker is a process with its own compiled twin; give a cluster with "
                   "--ray-address for more")
    opts.at_least("--batch-size", batch_size, 1)
    opts.count("--max-retries", max_retries, 0, MAX_RETRIES, "a task is retried when its "
               "worker died or it failed unexpectedly; one that fails this often will again")
    opts.solver_steps(max_steps)
    opts.finite("--tol", tol)
    if not 0 < tol < 1:
        raise opts.OptionError("--tol", f"a relative tolerance in (0, 1), got {tol:g}")
    opts.starts_and_refine(starts, refine, names)
    opts.choice("--grid", grid, ("orders", "hz"))
    opts.positive("--order-step", order_step)
    opts.input_speed_option("--f-max", f_max)
    opts.existing_file("--manifest", manifest)
    opts.check_out(out, True)  # a results folder is re-used by a re-run: only where it goes
    from dtwin.identify.fleet.identity import expand_records

    files = expand_records(records)  # nothing matching is refused before --out is created
    missing = [str(p) for p in files if not p.is_file()]
    if missing:
        raise opts.OptionError("RECORDS", f"no such file: {', '.join(missing[:5])}"
                               + (f" and {len(missing) - 5} more" if len(missing) > 5 else ""))

    gearbox = opts.load_gearbox(preset, spec, why="fleet identification needs the gearbox").spec
    if ray_address is not None and engine == "local":
        raise opts.OptionError("--engine", "--ray-address needs the ray engine (or auto)")
    if model is None and fault_location(names) is not None:
        kind = None  # a tooth fault's depth: the twin `dtwin severity` fits (one path)
    else:
        kind = twin_kind(gearbox, model)
        warn_torsional_tooth_fault(kind, names)
    settings = FleetSettings(free=tuple(names), kind=kind, f_sun=f_sun,
                             tacho=(reading["tacho"], reading["tacho_ppr"],
                                    reading["tacho_shaft"]) if reading else None,
                             starts=starts, refine=refine, max_steps=max_steps, tol=tol,
                             channel=opts.channel_token(channel), splits=splits,
                             grid=grid, order_step=order_step, f_max=f_max,
                             batch_size=batch_size,
                             max_retries=max_retries, discover=discover)
    _refuse_unusable_fleet(files, gearbox, settings)
    run = run_fleet(records, gearbox, out, settings, manifest=manifest,
                    engine="ray" if ray_address and engine == "auto" else engine,
                    address=ray_address, num_cpus=num_cpus,
                    progress=not (no_progress or is_quiet() or json_out), force=force)
    if json_out:
        _echo_json(run.to_dict())
    else:
        _print_run(run, discover)
        from dtwin.identify.fleet import load_results

        unconverged = [r for r in load_results(out, failed=False)
                       if r.get("kind", "fit") == "fit" and r.get("converged") is False]
        if unconverged:
            warn(f"{len(unconverged)} fitted record(s) did not converge ("
                 + "; ".join(f"{r.get('record', '?')}: {str(r.get('message', ''))[:80]}"
                             for r in unconverged[:3])
                 + ("; …" if len(unconverged) > 3 else "")
                 + "): their values are not final; raise --max-steps and run again with --force")

    failed = run.failed + (run.discover_failed if discover else 0)
    if failed:  # finished records are kept; a re-run retries the failed ones
        note(f"{failed} of {run.records} record(s) failed (exit code 1); the others are in "
             f"{out}; fix them and run the same command again")
        raise SystemExit(1)


def _print_run(run, discover: bool) -> None:
    """The run's summary on stdout (notes on stderr)."""
    for line in run.notes:
        note(f"note: {line}")

    typer.echo(f"{run.records} records: {run.skipped} already done, {run.fitted} fitted, "
               f"{run.failed} failed" + (f"; discovery {run.discovered} done, "
                                         f"{run.discover_failed} failed" if discover else "")
               + f" ({run.engine}, {run.wall_time_s:.1f} s)")
    for f in run.failures:
        typer.echo(f"  FAILED {f['record']} [{f.get('stage')}]: {f.get('error_type')}: "
                   f"{str(f.get('error')).splitlines()[0] if f.get('error') else ''}")
    if run.table is not None:
        typer.echo(f"table: {run.table}")


@fleet_app.command("table")
def fleet_table(
    results: Path = typer.Argument(..., help="Results folder of `dtwin fleet identify`."),
    csv_out: bool = typer.Option(False, "--csv", help="CSV instead of Parquet."),
    json_out: bool = typer.Option(False, "--json", help="Print the rows as JSON."),
    force: bool = typer.Option(False, "--force", help="Overwrite the existing table."),
) -> None:
    """Gather the per-record results into one table (a new file unless --force)."""
    from dtwin.identify.fleet import load_results, table_rows, write_table

    if not (results / "records").is_dir() and not (results / "failed").is_dir():
        raise opts.OptionError("RESULTS", f"{results} holds no fleet results (records/ or "
                               "failed/)")
    path, remark = write_table(results, force=force, fmt="csv" if csv_out else "auto")
    rows, names = table_rows(load_results(results))
    if json_out:
        _echo_json({"table": str(path), "rows": rows})
        return
    if remark:
        note(f"note: {remark}")
    head = f"{'machine':<14} {'timestamp':<26} {'status':<7} " + " ".join(
        f"{n:>26}" for n in names) + f" {'gap dB':>7}  record"
    typer.echo(head)
    for r in rows:
        cells = []
        for n in names:
            v, lo, hi = r.get(n), r.get(f"{n}_lo95"), r.get(f"{n}_hi95")
            cells.append(f"{'':>26}" if v is None else
                         f"{v:>9.4g} [{lo if lo is not None else float('nan'):.3g}, "
                         f"{hi if hi is not None else float('nan'):.3g}]".rjust(26))
        gap = r.get("gap_db")
        typer.echo(f"{str(r['machine']):<14} {str(r['timestamp'] or '-'):<26} "
                   f"{str(r['status']):<7} " + " ".join(cells)
                   + f" {gap if gap is not None else float('nan'):>7.2f}  {r['record']}")
    typer.echo(f"table: {path}")


@fleet_app.command("trends")
def fleet_trends(
    results: Path = typer.Argument(..., help="Results folder of `dtwin fleet identify`."),
    threshold: list[str] = typer.Option([], "--threshold", help="name>value, name<value or "
                                        "name<-20% (relative to the first record); repeatable."),
    horizon: float = typer.Option(90.0, "--horizon", help="Days ahead for 'approaching'."),
    out: Path | None = typer.Option(None, "--out", help="Folder of the figures and "
                                    "trends.json (default RESULTS/trends)."),
    json_out: bool = typer.Option(False, "--json", help="Print the trends as JSON."),
    force: bool = typer.Option(False, "--force", help="Overwrite an existing trends folder."),
) -> None:
    """Per-machine parameter trends and flags, a plot per machine and a fleet overview."""
    from dtwin.identify.fleet import load_results
    from dtwin.identify.plotting.fleet import plot_fleet_overview, plot_machine_trend
    from dtwin.identify.trends import machine_trends, parse_threshold

    from ..io.output import OutputFolder

    try:
        th = dict(parse_threshold(t) for t in threshold)
    except ValueError as e:
        raise opts.OptionError("--threshold", str(e)) from None
    opts.positive("--horizon", horizon, unit="days")
    if not results.is_dir():
        raise opts.OptionError("RESULTS", f"{results} is not a folder of fleet results")
    opts.check_out(out or results / "trends", force)
    rows = load_results(results, failed=False)

    if not rows:
        raise opts.OptionError("RESULTS", f"{results} holds no fitted record")
    trends = machine_trends(rows, th, horizon_days=horizon)
    report = {"results": str(results), "machines": {m: t.to_dict() for m, t in trends.items()}}
    with OutputFolder(out or results / "trends", force=force, staged=True,
                      parameters={"thresholds": th, "horizon_days": horizon}) as folder:
        folder.write_json("trends.json", report)
        for m, t in trends.items():
            safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in m)
            folder.savefig(f"trend_{safe}.png", plot_machine_trend(t))
        folder.savefig("overview.png", plot_fleet_overview(trends))
        _trend_extras(folder, results, trends, th, horizon)

    if json_out:
        _echo_json(report)
        return
    typer.echo(f"{'machine':<16} {'records':>7}  {'state':<12} flagged")
    for m, t in trends.items():
        flagged = "; ".join(f"{n}: {t.parameters[n].flag.reason}" for n in t.flagged)
        typer.echo(f"{m:<16} {len(t.records):>7}  {t.state:<12} {flagged or '-'}")
    note(f"wrote {folder.path}/trends.json, trend_<machine>.png, overview.png")



def _trend_extras(folder, results: Path, trends, thresholds, horizon: float) -> None:
    """The arrays (``trends.csv``/``.npz``: one row per machine, record and parameter) and the
    ``report.html`` of ``fleet trends``."""
    from dtwin.identify.tables import trend_rows

    from ..io.export import write_columns
    from ..report.html_report import write_html_report

    rows = trend_rows(trends)
    if rows:
        cols = {k: [r[k] for r in rows] for k in rows[0]}
        cols["time"] = [t or "" for t in cols["time"]]
        write_columns(folder, "trends", cols,
                      {"days": "d", "value": "SI (see unit)", "lower_95": "SI (see unit)",
                       "upper_95": "SI (see unit)"})
    figures = {"Fleet overview: latest value of each machine, trajectories": "overview.png"}
    for m in trends:
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in m)
        figures[f"Machine {m}"] = f"trend_{safe}.png"
    machines = [{"machine": m, "records": len(t.records), "state": t.state,
                 "flagged": "; ".join(f"{n}: {t.parameters[n].flag.reason}" for n in t.flagged)
                 or "-"} for m, t in trends.items()]
    write_html_report(
        folder, title=f"dtwin fleet trends: {results}",
        summary={"results": str(results), "machines": len(trends),
                 "thresholds": ", ".join(f"{k} {v[1]} {v[0]}" for k, v in thresholds.items())
                 or "none",
                 "horizon (days)": horizon},
        notes=[f"{r['machine']}: {r['flagged']}" for r in machines if r["flagged"] != "-"],
        figures=figures,
        tables={"Machines": machines, "Every record (95 % intervals)": rows})
