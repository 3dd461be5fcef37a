"""``dtwin discover``: find what the twin is missing, name it, add it, show the gap shrink.

    dtwin discover RECORD (--spec FILE | --preset NAME) [--kind torsional|translational]
                   [--channel C] [--sample-rate HZ] [--max-steps 3] [--alpha 0.01]
                   [--n-boot 400] [--seed 0] [--json] [--out DIR] [--force]

Runs :func:`dtwin.identify.discover.discover` (docs/discovery.md) on one channel of the record with
the spec's base twin. Terminal: one line per step (effect named, why, main parameter with its
99 % interval, held-out gap before → after) and the unexplained lines. ``--json``: the whole
result on stdout. ``--out DIR``: ``discover.json``, ``discover.md`` (readable report),
``gap.png`` (gap per step), ``spectrum_step<k>.png`` (measured vs model, residual lines marked,
full band and the first mesh band) and ``manifest.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from .app import app
from .cmd_spectrum import channel_token, load_gearbox, open_output, read_input


def _fmt_lines(lines, k=8) -> str:
    return "; ".join(f"{r.frequency:.2f} Hz (+{r.excess_db:.0f} dB, {r.text})" for r in lines[:k])


def markdown_report(result, record_name: str) -> str:
    """The readable report (Markdown) of a :class:`dtwin.identify.discover.DiscoveryResult`."""
    out = [f"# Discrepancy discovery: {record_name}", "",
           f"Input speed {result.f_sun:.4f} Hz (from the data); fm {result.kinematics.f_mesh:.2f} "
           f"Hz, fc {result.kinematics.f_carrier:.3f} Hz. Family-wise level per step "
           f"{result.settings.alpha:g} (Bonferroni over the candidates refit). Chance that a "
           f"random tone matches some kinematic combination at this resolution and order bound: "
           f"{100 * result.chance_match_probability:.1f} %.", "",
           f"Held-out gap of the base model: **{result.initial_gap.total:.2f} dB**; final: "
           f"**{result.final_gap.total:.2f} dB**. Stopped: {result.stop_reason}.", "",
           "![gap](gap.png)", "", "![base](spectrum_step0.png)", ""]
    for s in result.steps:
        out += [f"## Step {s.number}: {s.named}", "",
                f"- effect fitted: `{s.effect}` (group `{s.group}`"
                + (f"; not told apart from {', '.join(s.indistinguishable_from)}"
                   if s.indistinguishable_from else "") + ")",
                f"- why: residual lines {_fmt_lines(s.matched_lines)}"
                + (f"; on the effect's signature: {', '.join(sorted(set(filter(None, s.matched_labels)))[:8])}"
                   if any(s.matched_labels) else ""),
                f"- held-out gap {s.gap_before.total:.2f} → {s.gap_after.total:.2f} dB "
                f"(full model confirmed: {s.gap_confirmed.total:.2f} dB); p = {s.p_value:.2g} "
                f"≤ {s.level:.2g}",
                f"- {s.main['name']}: {s.main['value']:.4g} {s.main['unit']}, 99 % interval "
                f"[{s.main['interval'][0]:.3g}, {s.main['interval'][1]:.3g}] (typical on real "
                f"machines {s.main['typical_range'][0]:g}–{s.main['typical_range'][1]:g}: "
                f"{s.main['typical_note']})", "",
                "| parameter | value | 99 % interval | unit |", "|---|---|---|---|"]
        for p in s.parameters:
            out.append(f"| {p['name']} | {p['value']:.4g} | [{p['interval'][0]:.3g}, "
                       f"{p['interval'][1]:.3g}] | {p['unit']} |")
        out += ["", "| candidate refit | group | coverage | p | held-out gap (dB) | identified |",
                "|---|---|---|---|---|---|"]
        for c in s.candidates:
            out.append(f"| {c.name} | {c.group} | {c.coverage:.2f} | {c.p_value:.3g} | "
                       f"{c.gap_after:.2f} | {c.identified} |")
        out += ["", f"![step {s.number}](spectrum_step{s.number}.png)", ""]
    out += ["## Unexplained lines", ""]
    if result.unexplained:
        out += ["| f (Hz) | excess (dB) | over floor (dB) | kinematic description |",
                "|---|---|---|---|"]
        out += [f"| {r.frequency:.2f} | {r.excess_db:.1f} | {r.above_floor_db:.1f} | {r.text} |"
                for r in result.unexplained]
    else:
        out.append("None.")
    if result.extra_in_model:
        out += ["", "Lines in the model but not in the measurement: "
                + _fmt_lines(result.extra_in_model, 20)]
    return "\n".join(out) + "\n"


@app.command()
def discover(
    record_file: Path = typer.Argument(..., help="Record file (any supported format)."),
    spec: Path | None = typer.Option(None, "--spec", help="Gearbox spec file (TOML)."),
    preset: str | None = typer.Option(None, "--preset", help="Gearbox preset instead of --spec."),
    kind: str | None = typer.Option(None, "--kind", help="Base model: torsional/translational "
                                                         "(default: the spec's model.kind)."),
    channel: str = typer.Option("0", "--channel", help="Channel name or index."),
    sample_rate: float | None = typer.Option(None, "--sample-rate",
                                             help="Sampling rate (Hz) for formats without one."),
    max_steps: int = typer.Option(3, "--max-steps", help="Budget of effects added."),
    alpha: float = typer.Option(0.01, "--alpha", help="Family-wise level per step (<= 0.01)."),
    n_boot: int = typer.Option(400, "--n-boot", help="Bootstrap draws of the null statistic."),
    seed: int = typer.Option(0, "--seed", help="Seed of the bootstrap."),
    json_out: bool = typer.Option(False, "--json", help="Print the result as JSON on stdout."),
    out: Path | None = typer.Option(None, "--out", help="Write discover.json/.md, PNGs."),
    force: bool = typer.Option(False, "--force", help="Overwrite results in --out."),
) -> None:
    """Find where twin and measurement disagree, name the missing effect, add it, refit."""
    from dtwin.identify.discover import DiscoverySettings
    from dtwin.identify.discover import discover as run

    from ..errors import SpecError
    from ..io.output import to_jsonable

    gearbox = load_gearbox(preset, spec)
    if gearbox is None:
        raise SpecError([("--spec", "discover needs the gearbox: pass --spec FILE or --preset")])
    if not 0 < alpha <= 0.01:
        raise SpecError([("--alpha", f"must lie in (0, 0.01], got {alpha}")])
    record = read_input(record_file, sample_rate)
    ch = channel_token(channel)
    settings = DiscoverySettings(alpha=alpha, n_boot=n_boot, max_steps=max_steps, seed=seed)
    log = None if json_out else (lambda s: typer.echo(s, err=True))
    result = run(record.channel(ch), gearbox, sample_rate=record.sample_rate, kind=kind,
                 settings=settings, log=log)
    report = {"record": str(record_file), "channel": str(channel), **result.to_dict()}
    if json_out:
        typer.echo(json.dumps(to_jsonable(report), indent=2))
    else:
        typer.echo(f"base model: held-out gap {result.initial_gap.total:.2f} dB")
        for s in result.steps:
            typer.echo(f"step {s.number}: {s.named:28s} gap {s.gap_before.total:6.2f} → "
                       f"{s.gap_after.total:6.2f} dB  p={s.p_value:.2g}  {s.main['name']} "
                       f"{s.main['value']:.3g} {s.main['unit']} "
                       f"[{s.main['interval'][0]:.3g}, {s.main['interval'][1]:.3g}]")
        typer.echo(f"stopped: {result.stop_reason}")
        for r in result.unexplained[:15]:
            typer.echo(f"unexplained: {r.frequency:9.2f} Hz  +{r.excess_db:5.1f} dB  {r.text}")
    if out is not None:
        from dtwin.identify.plotting.discover import plot_gap_bars, plot_step_spectra

        unit = record.units[record.index(ch)] or "-"
        folder = open_output(out, force, [record_file, spec], gearbox,
                             {"channel": str(channel), "kind": kind, "max_steps": max_steps,
                              "alpha": alpha, "n_boot": n_boot, "seed": seed})
        folder.write_json("discover.json", report)
        folder.write_text("discover.md", markdown_report(result, record_file.name))
        folder.savefig("gap.png", plot_gap_bars(result))
        for k in range(len(result.models)):
            folder.savefig(f"spectrum_step{k}.png", plot_step_spectra(result, k, unit=unit))
            band = (result.kinematics.f_mesh - 12 * result.kinematics.f_carrier,
                    result.kinematics.f_mesh + 12 * result.kinematics.f_carrier)
            folder.savefig(f"spectrum_step{k}_mesh.png",
                           plot_step_spectra(result, k, band=band, unit=unit))
        if not json_out:
            typer.echo(f"wrote {folder.path}/discover.json, discover.md, gap.png, "
                       "spectrum_step*.png, manifest.json", err=True)
