"""``dtwin identify`` and ``dtwin severity``: fit the twin to records (:mod:`dtwin.identify`).

    dtwin identify RECORD... (--spec FILE | --preset NAME)
                   --free k_sun_planet,k_ring_planet,zeta_mesh,sun_fault
                   [--model torsional|translational] [--f-sun HZ] [--runup LOW HIGH]
                   [--solver lm|gauss-newton|dogleg] [--starts N] [--refine K] [--jac fwd|rev]
                   [--max-steps N] [--channel C] [--json] [--out DIR] [--force]

    dtwin severity RECORD (--spec FILE | --preset NAME) [--location sun|planet|ring]
                   [--free extra,names] [--f-sun HZ] [--json] [--out DIR] [--force]

Free names come from the parameter registry (``dtwin.registry``); an unknown name, an
unreadable record, NaN samples, a rate under 2.5 × f_mesh or a record too short for the carrier
sidebands fail with a clear message (exit code 2) before anything is simulated. The input speed
is estimated from each record (mesh harmonics, or its tachometer) unless ``--f-sun`` is given;
``--runup LOW HIGH`` (Hz) marks the records as run-ups/coast-downs within that speed range
(speed profile by order tracking, spectrogram residuals).

Terminal: the parameter table (initial, fitted, 95 % interval, "NOT DETERMINED" flags) and the
loss. ``--json``: the result on stdout. ``--out DIR``: ``identify.json`` (values, intervals,
correlations, singular values, loss history, operating points), ``spectrum_fit.png`` (measured
vs fitted levels, peaks labelled; one per record), ``loss.png`` and ``manifest.json``;
``dtwin severity`` writes ``severity.json`` and ``spectrum_fit.png``.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from ..errors import SpecError
from .app import app


def _gearbox(preset: str | None, spec_file: Path | None):
    from .cmd_spectrum import load_gearbox

    g = load_gearbox(preset, spec_file)
    if g is None:
        raise SpecError([("--spec/--preset", "identification needs the gearbox: pass --spec FILE "
                          "or --preset NAME")])
    return g


def _records(paths: list[Path], sample_rate: float | None):
    from .cmd_spectrum import read_input

    return [read_input(p, sample_rate) for p in paths]


def _write(out, force, inputs, gearbox, params, result, name: str, extra: dict) -> Path:
    from dtwin.identify.api import plot_fit
    from dtwin.identify.plotting.fit import plot_loss_history

    from .cmd_spectrum import open_output

    folder = open_output(out, force, inputs, gearbox, params)
    folder.write_json(name, extra)
    for i in range(len(result.problem.observations)):
        suffix = "" if len(result.problem.observations) == 1 else f"_{i}"
        folder.savefig(f"spectrum_fit{suffix}.png", plot_fit(result, i))
    folder.savefig("loss.png", plot_loss_history(result.loss_history))
    return folder.path


@app.command()
def identify(
    records: list[Path] = typer.Argument(..., help="Record file(s), fitted jointly."),
    free: str = typer.Option(..., "--free", help="Comma-separated registry names to fit."),
    spec: Path | None = typer.Option(None, "--spec", help="Gearbox spec file (TOML)."),
    preset: str | None = typer.Option(None, "--preset", help="Gearbox preset."),
    model: str = typer.Option("torsional", "--model", help="torsional or translational twin."),
    f_sun: float | None = typer.Option(None, "--f-sun", help="Input speed (Hz); default: "
                                       "estimated from each record."),
    runup: tuple[float, float] | None = typer.Option(None, "--runup", help="Run-up records: "
                                                     "speed range LOW HIGH (Hz)."),
    solver: str = typer.Option("lm", "--solver", help="lm, gauss-newton or dogleg."),
    starts: int = typer.Option(1, "--starts", help="Grid starts evaluated in one batch."),
    refine: int = typer.Option(1, "--refine", help="Best starts refined by the solver."),
    jac: str = typer.Option("fwd", "--jac", help="fwd (forward mode) or rev (reverse)."),
    max_steps: int = typer.Option(40, "--max-steps", help="Solver steps."),
    channel: str = typer.Option("0", "--channel", help="Channel name or index."),
    sample_rate: float | None = typer.Option(None, "--sample-rate", help="Rate (Hz) if the "
                                             "file states none."),
    json_out: bool = typer.Option(False, "--json", help="Print the result as JSON on stdout."),
    out: Path | None = typer.Option(None, "--out", help="Write JSON, PNGs and a manifest."),
    force: bool = typer.Option(False, "--force", help="Overwrite results in --out."),
    progress: bool = typer.Option(False, "--progress", help="Print the stages and losses."),
) -> None:
    """Fit twin parameters (registry names) to measured spectra, with 95 % intervals."""
    from dtwin.identify.fit import check_free, fit

    from .cmd_spectrum import channel_token

    names = check_free(free)  # unknown names fail before anything is read or simulated
    gearbox = _gearbox(preset, spec)
    recs = _records(records, sample_rate)
    res = fit(recs, gearbox, names, kind=model, f_sun=f_sun,
              runup=tuple(runup) if runup else None, solver=solver, starts=starts,
              refine=refine, jac=jac, max_steps=max_steps, channel=channel_token(channel),
              progress=progress)
    report = {"records": [str(p) for p in records], "gearbox": preset or str(spec),
              "model": model, **res.to_dict()}
    if json_out:
        from ..io.output import to_jsonable

        typer.echo(json.dumps(to_jsonable(report), indent=2))
    else:
        typer.echo(res.table())
    if out is not None:
        path = _write(out, force, list(records) + [spec], gearbox,
                      {"free": names, "solver": solver, "starts": starts, "refine": refine,
                       "jac": jac, "model": model}, res, "identify.json", report)
        if not json_out:
            typer.echo(f"wrote {path}/identify.json, spectrum_fit.png, loss.png, manifest.json",
                       err=True)


@app.command()
def severity(
    record: Path = typer.Argument(..., help="Record file."),
    spec: Path | None = typer.Option(None, "--spec", help="Gearbox spec file (TOML)."),
    preset: str | None = typer.Option(None, "--preset", help="Gearbox preset."),
    location: str = typer.Option("sun", "--location", help="sun, planet or ring."),
    free: str = typer.Option("", "--free", help="Further registry names fitted with it."),
    model: str = typer.Option("torsional", "--model", help="torsional or translational twin."),
    f_sun: float | None = typer.Option(None, "--f-sun", help="Input speed (Hz)."),
    channel: str = typer.Option("0", "--channel", help="Channel name or index."),
    sample_rate: float | None = typer.Option(None, "--sample-rate", help="Rate (Hz)."),
    json_out: bool = typer.Option(False, "--json", help="Print the result as JSON on stdout."),
    out: Path | None = typer.Option(None, "--out", help="Write JSON, PNG and a manifest."),
    force: bool = typer.Option(False, "--force", help="Overwrite results in --out."),
) -> None:
    """Severity of the fault at a location, with its 95 % interval."""
    from dtwin.identify.fit import check_free
    from dtwin.identify.severity import estimate_severity

    from .cmd_spectrum import channel_token

    extra = check_free(free) if free.strip() else []
    check_free([f"{location}_fault"]) if location in ("sun", "planet", "ring") else None
    gearbox = _gearbox(preset, spec)
    (rec,) = _records([record], sample_rate)
    est = estimate_severity(rec, gearbox, location, free=extra, kind=model, f_sun=f_sun,
                            channel=channel_token(channel))
    report = {"record": str(record), "gearbox": preset or str(spec), **est.to_dict()}
    if json_out:
        from ..io.output import to_jsonable

        typer.echo(json.dumps(to_jsonable(report), indent=2))
    else:
        lo, hi = est.interval
        typer.echo(f"{location} fault severity {est.severity:.3f}  95 % [{lo:.3f}, {hi:.3f}] "
                   f"({est.method})" + ("" if est.determined else "  NOT DETERMINED"))
        typer.echo(est.fit.table())
    if out is not None:
        _write(out, force, [record, spec], gearbox, {"location": location, "free": extra},
               est.fit, "severity.json", report)
