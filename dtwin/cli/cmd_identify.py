"""``dtwin identify`` and ``dtwin severity``: fit the twin to records (:mod:`dtwin.identify`).

    dtwin identify RECORD... (--spec FILE | --preset NAME)
                   --free k_sun_planet,k_ring_planet,zeta_mesh,sun_fault
                   [--model torsional|translational] [--f-sun HZ] [--tacho CHANNEL[:PPR]]
                   [--runup LOW HIGH]
                   [--solver lm|gauss-newton|dogleg] [--starts N] [--refine K] [--jac fwd|rev]
                   [--max-steps N] [--channel C] [--fit-window auto|full|START:LENGTH]
                   [--splits/--no-splits] [--json] [--out DIR] [--force]

    dtwin severity RECORD (--spec FILE | --preset NAME) [--location sun|planet|ring]
                   [--free extra,names] [--f-sun HZ] [--tacho CHANNEL[:PPR]]
                   [--fit-window auto|full|START:LENGTH]
                   [--low-band/--no-low-band] [--jackknife/--no-jackknife] [--shapes]
                   [--splits/--no-splits] [--flanks/--no-flanks]
                   [--json] [--out DIR] [--force]

Free names come from the parameter registry (``dtwin.model.registry``); an unknown name, an
unreadable record, NaN samples, a rate under 2.5 × f_mesh or a record too short for the carrier
sidebands fail with a clear message (exit code 2) before anything is simulated. The input speed
is ``--f-sun``, else each record's tachometer (``--tacho``), metadata or mesh lines
(:func:`dtwin.identify.operating_point.resolve_speed`); a record that shows no mesh line at
that speed nor near the spec's, and a ``--f-sun`` more than 1 % off the record's lines, are
refused before the fit, a smaller disagreement and a tachometer or metadata speed the lines
contradict are warned about, naming the lines
(:func:`dtwin.cli.options.check_speed_against_lines`);
``--runup LOW HIGH`` (Hz) marks the records as run-ups/coast-downs within that speed range
(speed profile by order tracking, spectrogram residuals).

A steady record longer than the fit needs is fitted on a window (:mod:`dtwin.identify.segment`):
by default the steadiest ``max(4 s, 20 carrier periods)``, decimated to the rate its first four
mesh harmonics need; ``--fit-window START:LENGTH`` (s) places it, ``full`` fits the whole record
at its own rate. Shorter records are fitted whole, as they are. The report says what was fitted
(``fit_windows``: "fitted on 4.0 s of 60.0 s …, decimated to 5120 Hz"). Run-ups are fitted
whole unless ``START:LENGTH`` is given.

Terminal: the parameter table (initial, fitted, 95 % interval, "NOT DETERMINED" flags) and the
loss. ``--json``: the result on stdout. ``--out DIR``: ``identify.json`` (values, intervals,
correlations, singular values, loss history, operating points), ``spectrum_fit.png`` (measured
vs fitted levels, peaks labelled; one per record), ``loss.png`` and ``manifest.json``;
``dtwin severity`` writes ``severity.json`` and ``spectrum_fit.png``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import typer

from ..signal.units import unit_name
from . import options as opts
from .app import app


def _check_common(model: str | None, f_sun: float | None, out: Path | None, force: bool) -> None:
    opts.choice("--model", model, ("torsional", "translational"))
    opts.input_speed_option("--f-sun", f_sun)
    opts.check_out(out, force)


def _records(paths: list[Path], sample_rate: float | None, channel: str | int, spec,
             f_sun: float | None, tacho: str | None = None):
    """Read and check the records of a fit (refused if unusable or degraded)."""
    recs = [opts.read_record(p, sample_rate, tacho) for p in paths]
    for r in recs:
        opts.check_channel(r, channel)
        opts.checked_record(r, channel, spec, f_sun, fit=True)
    return recs


def fit_window_option():
    return typer.Option("auto", "--fit-window", help="Stretch of each record the fit uses: "
                        "auto (a steady max(4 s, 20 carrier periods), decimated to the rate "
                        "four mesh harmonics need; shorter records whole), full (the whole "
                        "record at its rate) or START:LENGTH in seconds.")


def _parse_window(text: str):
    """``--fit-window`` checked before any work (:class:`dtwin.identify.segment.FitWindow`)."""
    from dtwin.identify.segment import FitWindow

    from ..errors import SettingsError

    try:
        return FitWindow.parse(text)
    except SettingsError as e:
        raise opts.OptionError("--fit-window", str(e)) from None


def _windows(recs: list, spec, f_sun: float | None, window, channel) -> list:
    """The segment of each record that its fit uses
    (:func:`dtwin.identify.segment.segment_for_fit`); a window that does not fit a record is an
    ``--fit-window`` error."""
    from dtwin.identify.segment import segment_for_fit

    from ..errors import SettingsError

    segs = []
    for r in recs:
        try:
            segs.append(segment_for_fit(r, spec, f_sun, window, channel=channel))
        except SettingsError as e:
            raise opts.OptionError("--fit-window", str(e)) from None
    return segs


def _segments(paths: list[Path], sample_rate: float | None, channel: str | int, spec,
              f_sun: float | None, window, tacho: str | None = None) -> list:
    """Read and check the records of a fit and cut the segment each fit uses
    (:func:`_records`, :func:`_windows`). The whole records are let go before the fit and
    their memory handed back to the system (:func:`dtwin._heap.release`): a 60 s, 25.6 kHz
    record holds ~60 MB that its 4 s window does not need."""
    from dtwin import _heap

    segs = _windows(_records(paths, sample_rate, channel, spec, f_sun, tacho), spec, f_sun,
                    window, channel)
    _heap.release()
    return segs


def _window_report(segs: list) -> dict:
    """``fit_windows`` for the report when a fit saw less than a whole record."""
    if not any(s.windowed for s in segs):
        return {}
    return {"fit_windows": [s.to_dict() for s in segs]}


def _echo_windows(segs: list) -> None:
    for s in segs:
        if s.windowed:
            typer.echo(s.describe())


def _unit(recs: list, channel) -> str | None:
    """The unit of the fitted channel as the first record states it (None when it does not)."""
    return recs[0].units[recs[0].index(channel)]


def _severity_headline(est) -> dict:
    """The severity estimate as the report's first rows: severity and peak stiffness loss with
    their 95 % intervals, the status."""
    lo, hi = est.interval
    plo, phi = est.peak_interval
    return {f"{est.location} fault severity (dimensionless)":
            f"{est.severity:.3g}, 95 % [{lo:.3g}, {hi:.3g}] ({est.method})",
            "peak stiffness loss (% of the mean mesh stiffness)":
            f"{100 * est.peak_loss:.1f}, 95 % [{100 * plo:.1f}, {100 * phi:.1f}]",
            **({"planet tooth flank": est.flank} if est.flank else {}),
            "status": est.status}


def _files(result, name: str, report: dict, unit: str | None, headline: dict | None = None):
    """The files of a fit result: the report, one spectrum figure per record (levels in the
    records' `unit`; ``record unit`` when they state none), the loss; `headline` (quantity →
    text) opens the HTML report's summary."""
    def files() -> dict:
        from dtwin.identify.api import plot_fit
        from dtwin.identify.plotting.fit import plot_loss_history
        from dtwin.identify.tables import fit_rows

        from ..io.export import Columns
        from ..report.html_report import HTMLReport

        n = len(result.problem.observations)
        out = {name: report}
        figures = {}
        for i, (f, meas, fitted) in enumerate(result.spectra()):
            stem = f"spectrum_fit{'' if n == 1 else f'_{i}'}"
            out[f"{stem}.png"] = plot_fit(result, i, unit=unit)
            out[f"{stem}.csv"] = Columns({"frequency": f, "measured": meas, "fitted": fitted},
                                         {"frequency": "Hz", "measured": unit_name(unit),
                                          "fitted": unit_name(unit)})
            figures[f"Measured vs fitted spectrum, record {i}"] = f"{stem}.png"
        if result.loss_history:  # none for a depth read from the sideband ratio
            out["loss.png"] = plot_loss_history(result.loss_history)
            out["loss.csv"] = Columns(
                {"evaluation": list(range(1, len(result.loss_history) + 1)),
                 "loss": result.loss_history}, {"evaluation": "1", "loss": "1"})
            figures["Loss over the solver's evaluations"] = "loss.png"
        records = report.get("records") or [report.get("record")]
        out["report.html"] = HTMLReport(
            title=f"dtwin {name.split('.')[0]}: {', '.join(Path(str(r)).name for r in records)}",
            summary={**(headline or {}),
                     "records": ", ".join(map(str, records)), "gearbox": report.get("gearbox"),
                     "loss": result.loss, "iterations": result.iterations,
                     "converged": result.converged, "wall time (s)": result.wall_time},
            notes=[f"{k}: not determined by these data ({v})"
                   for k, v in result.not_determined.items()]
            + ([result.message] if result.message != "converged" else []),
            figures=figures,
            tables={"Fitted parameters (95 % intervals)": fit_rows(result),
                    "Operating points": result.operating_points,
                    **({"Excitation/response splits fitted (dtwin.identify.split)": [
                        {"split": r["excitation"], "loss": r["loss"], **r["values"],
                         "reported": r["excitation"] == result.excitation,
                         "accepted": r["accepted"]} for r in result.splits]}
                       if getattr(result, "splits", None) else {})})
        return out

    return files


@app.command()
def identify(
    records: list[Path] = typer.Argument(..., help="Record file(s), fitted jointly."),
    free: str = typer.Option(..., "--free", help="Comma-separated registry names to fit."),
    spec: Path | None = opts.spec_option(),
    preset: str | None = opts.preset_option(),
    model: str | None = typer.Option(None, "--model", help="torsional or translational twin "
                                     "(default: the kind a calibrated spec was calibrated "
                                     "with, otherwise torsional; a tooth fault's severity on "
                                     "one steady record is fitted as `dtwin severity` fits "
                                     "it, with its twin)."),
    f_sun: float | None = opts.f_sun_option("Input speed (Hz) of every record; "),
    tacho: str | None = opts.tacho_option(),
    runup: tuple[float, float] | None = typer.Option(None, "--runup", help="Run-up records: "
                                                     "speed range LOW HIGH (Hz)."),
    solver: str = typer.Option("lm", "--solver", help="lm, gauss-newton or dogleg."),
    starts: int = typer.Option(1, "--starts", parser=opts.whole_number,
                               help="Grid starts evaluated in one batch."),
    refine: int = typer.Option(1, "--refine", parser=opts.whole_number,
                               help="Best starts refined by the solver."),
    jac: str = typer.Option("fwd", "--jac", help="fwd (forward mode) or rev (reverse)."),
    max_steps: int = typer.Option(40, "--max-steps", parser=opts.whole_number,
                                  help="Solver steps."),
    channel: str = opts.channel_option(),
    fit_window: str = fit_window_option(),
    splits: bool | None = opts.splits_option("a fault severity is free"),
    sample_rate: float | None = opts.sample_rate_option(),
    json_out: bool = opts.json_option(),
    out: Path | None = opts.out_option("identify.json, spectrum_fit.png, loss.png"),
    force: bool = opts.force_option(),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Print the stages "
                                  "and losses on stderr (default; `dtwin --quiet` silences it)."),
) -> None:
    """Fit twin parameters (registry names) to measured spectra, with 95 % intervals."""
    from dtwin.identify.fit import SOLVERS, fit
    from dtwin.identify.severity import estimate_severity, fault_location

    from ..spec.build import twin_kind, warn_torsional_tooth_fault

    names = opts.free_names("--free", free)  # before anything is read or simulated
    _check_common(model, f_sun, out, force)
    opts.choice("--solver", solver, SOLVERS)
    opts.choice("--jac", jac, ("fwd", "rev"))
    opts.starts_and_refine(starts, refine, names)
    opts.solver_steps(max_steps)
    window = _parse_window(fit_window)
    opts.tacho_reading(tacho)
    if runup is not None and window.start is None:
        window = dataclasses.replace(window, whole=True)  # a run-up is fitted whole by default
    if runup is not None:
        opts.band("--runup", runup)
        if runup[0] <= 0:
            raise opts.OptionError("--runup", f"LOW must be > 0 Hz, got {runup[0]:g}")
        opts.input_speed_option("--runup", runup[1])
    gb = opts.load_gearbox(preset, spec, why="identification needs the gearbox")
    asked = None if model is None else twin_kind(gb.spec, model)
    model = twin_kind(gb.spec, model)
    one_depth = runup is None and len(records) == 1 and fault_location(names) is not None
    # a tooth fault's depth on one record is fitted with severity's twin unless one is asked
    warn_torsional_tooth_fault(asked if one_depth else model, names)
    ch = opts.channel_token(channel)
    segs = _segments(records, sample_rate, ch, gb.spec, f_sun, window, tacho)
    recs = [sg.record for sg in segs]
    if runup is None:
        for p, r in zip(records, recs, strict=True):
            opts.check_speed_against_lines(r, gb.spec, f_sun, ch, p)
    from .progress import progress as shown
    from .progress import record_size

    # one tooth fault's depth on one steady record: the problem `dtwin severity` fits
    location = fault_location(names) if one_depth else None
    est = None
    with shown("identify", json_out=json_out, size=record_size(recs[0]),
               enabled=progress) as stage:
        if location is not None:
            est = estimate_severity(recs[0], gb.spec, location,
                                    free=[n for n in names if n != f"{location}_fault"],
                                    kind=asked, f_sun=f_sun, solver=solver, starts=starts,
                                    refine=refine, jac=jac, max_steps=max_steps, channel=ch,
                                    splits=splits, progress=stage.enabled)
            res = est.fit
            model = res.problem.twin.kind
        else:
            res = fit(recs, gb.spec, names, kind=model, f_sun=f_sun,
                      runup=tuple(runup) if runup else None, solver=solver, starts=starts,
                      refine=refine, jac=jac, max_steps=max_steps, channel=ch, splits=splits,
                      progress=stage.enabled)
    report = {"records": [str(p) for p in records], "gearbox": gb.source,
              "model": model, **_window_report(segs), **res.to_dict()}
    if est is not None:
        report["severity"] = est.to_dict(with_fit=False)

    def table() -> None:
        _echo_windows(segs)
        if est is not None:
            typer.echo(est.summary())  # the depth `dtwin severity` reports for this record
            if est.note:
                typer.echo(f"note: {est.note}")
        typer.echo(res.table())

    opts.emit(report, json_out=json_out, table=table, out=out,
              force=force, files=_files(res, "identify.json", report, _unit(recs, ch)),
              inputs=records,
              gearbox=gb, parameters={"free": names, "solver": solver, "starts": starts,
                                      "refine": refine, "jac": jac, "model": model,
                                      "fit_window": window.text(), "splits": splits})


@app.command()
def severity(
    record: Path = typer.Argument(..., help="Record file."),
    spec: Path | None = opts.spec_option(),
    preset: str | None = opts.preset_option(),
    location: str = typer.Option("sun", "--location", help="sun, planet or ring."),
    free: str = typer.Option("", "--free", help="Further registry names fitted with it."),
    model: str | None = typer.Option(None, "--model", help="torsional or translational twin "
                                     "(default: translational, whatever the spec says: the "
                                     "torsional twin's sun and planets cannot move sideways "
                                     "under a tooth fault, and it reads sun and planet faults "
                                     "4–10× small)."),
    f_sun: float | None = opts.f_sun_option(),
    tacho: str | None = opts.tacho_option(),
    channel: str = opts.channel_option(),
    fit_window: str = fit_window_option(),
    low_band: bool | None = typer.Option(
        None, "--low-band/--no-low-band",
        help="Also fit the fault's impulse comb below the first mesh band (band 0), where a "
             "tooth fault makes its strongest lines (default: on for a sun or ring fault on a "
             "steady record)."),
    jackknife: bool = typer.Option(
        True, "--jackknife/--no-jackknife",
        help="Widen the interval by the delete-one-band jackknife when the bands disagree "
             "beyond their noise (a model-form error); the status says so."),
    shapes: bool = typer.Option(
        False, "--shapes",
        help="Also fit the loss's shape (sharp, soft, felt beyond the tooth's contact, "
             "confined to its middle like a pit): the intervals become the union over the "
             "shapes the record cannot reject. One fit per shape."),
    splits: bool | None = opts.splits_option("the calibration fitted an excitation or a "
                                             "response shape", "One more fit per shape."),
    flanks: bool | None = typer.Option(
        None, "--flanks/--no-flanks",
        help="For a planet fault, fit it on each flank of the planet tooth (both, the one "
             "meeting the sun, the one meeting the ring) and report the flank the record "
             "prefers; a planet fault on the wrong flank reads many times small (default: on "
             "unless the spec's [[faults]] entry names the planet fault's flank). Three fits "
             "where there was one."),
    method: str | None = typer.Option(
        None, "--method",
        help="ratio: read the depth from the power of the fault's sidebands over the healthy "
             "mesh lines (the default with no --free on a steady record); spectrum: fit the "
             "spectrum's log levels (the default otherwise; --low-band, --jackknife, --splits "
             "and --flanks are its)."),
    healthy: Path | None = typer.Option(
        None, "--healthy",
        help="A healthy record of the same machine at the same speed and rate (e.g. the one "
             "calibrated on): lines it already holds are not counted as the fault's "
             "(--method ratio)."),
    sample_rate: float | None = opts.sample_rate_option(),
    json_out: bool = opts.json_option(),
    out: Path | None = opts.out_option("severity.json, spectrum_fit.png, loss.png"),
    force: bool = opts.force_option(),
) -> None:
    """Severity of the fault at a location, with its 95 % interval."""
    from dtwin.identify.fit import check_free
    from dtwin.identify.severity import estimate_severity

    from ..spec.build import twin_kind

    opts.choice("--location", location, ("sun", "planet", "ring"))
    extra = opts.free_names("--free", free) if free.strip() else []
    check_free([f"{location}_fault"])
    opts.choice("--method", method, ("ratio", "spectrum"))
    if method == "ratio" and extra:
        raise opts.OptionError("--method", "the sideband ratio reads the fault's depth alone: "
                               "leave out --free or use --method spectrum")
    if healthy is not None and not healthy.is_file():
        raise opts.OptionError("--healthy", f"{healthy} does not exist; give the path of a "
                               "healthy record of the same machine")
    _check_common(model, f_sun, out, force)
    window = _parse_window(fit_window)
    opts.tacho_reading(tacho)
    gb = opts.load_gearbox(preset, spec, why="severity estimation needs the gearbox")
    if model is not None:  # asked for: checked against a calibrated spec's (a warning)
        model = twin_kind(gb.spec, model)
    ch = opts.channel_token(channel)
    segs = _segments([record], sample_rate, ch, gb.spec, f_sun, window, tacho)
    rec = segs[0].record
    opts.check_speed_against_lines(rec, gb.spec, f_sun, ch, record)
    healthy_rec = None
    if healthy is not None:
        healthy_rec = _segments([healthy], sample_rate, ch, gb.spec, f_sun, window,
                                tacho)[0].record
    from .progress import progress, record_size

    with progress("severity", json_out=json_out, size=record_size(rec)):
        est = estimate_severity(rec, gb.spec, location, free=extra, kind=model, f_sun=f_sun,
                                channel=ch, low_band=low_band, jackknife=jackknife,
                                ramps="shapes" if shapes else None, splits=splits,
                                flanks=flanks, method=method, healthy=healthy_rec)

    report = {"record": str(record), "gearbox": gb.source, **_window_report(segs),
              **est.to_dict()}

    def table() -> None:
        _echo_windows(segs)
        typer.echo(est.summary())  # severity and peak stiffness loss, 95 %, status
        if est.note:
            typer.echo(f"note: {est.note}")
        if est.shapes_table():
            typer.echo(est.shapes_table())
        typer.echo(est.readings_table() if est.readings else est.fit.table())

    opts.emit(report, json_out=json_out, table=table, out=out, force=force,
              files=_files(est.fit, "severity.json", report, _unit([rec], ch),
                           _severity_headline(est)), inputs=[record],
              gearbox=gb,
              parameters={"location": location, "free": extra,
                          "fit_window": window.text(), "low_band": low_band,
                          "jackknife": jackknife, "shapes": shapes, "splits": splits,
                          "flanks": flanks, "method": method,
                          "healthy": None if healthy is None else str(healthy)})
