"""``dtwin discover``: find what the twin is missing, name it, add it, show the gap shrink.

    dtwin discover RECORD (--spec FILE | --preset NAME) [--kind torsional|translational]
                   [--channel C] [--f-sun HZ] [--tacho CHANNEL[:PPR[:SHAFT]]]
                   [--sample-rate HZ] [--max-steps 3] [--alpha 0.01]
                   [--n-boot 400] [--seed 0] [--json] [--out DIR] [--force]

Runs :func:`dtwin.identify.discover.discover` (docs/discovery.md) on one channel of the record with
the spec's base twin. Terminal (:func:`screen_summary`): one line per step (effect named, why,
main parameter with its 99 % interval, held-out gap before → after), one line per refit
candidate and step with its verdict (identified or not, accepted or set aside and why), and the
unexplained lines. ``--json``: the whole result on stdout. ``--out DIR``: ``discover.json``,
``discover.md`` (readable report), ``report.html``, ``gap.png`` (gap per step),
``spectrum_step<k>.png`` (measured vs model, residual lines marked, full band and the first
mesh band), ``spectra.csv``/``.npz`` and ``manifest.json``. Every output takes its candidate
verdicts from :meth:`dtwin.identify.discover.DiscoveryResult.candidate_table`.
"""

from __future__ import annotations

from pathlib import Path

import typer

from ..signal.units import unit_name
from . import options as opts
from .app import app


def _fmt_lines(lines, k=8) -> str:
    return "; ".join(f"{r.frequency:.2f} Hz (+{r.excess_db:.0f} dB, {r.text})" for r in lines[:k])


def _unit_text(unit: str) -> str:
    """A unit as printed: "dimensionless" for 1."""
    return "dimensionless" if unit in ("1", "") else unit


def _score(row: dict) -> str:
    """A candidate's screening score at zero amplitude, its degrees of freedom and rank (a row
    of :meth:`dtwin.identify.discover.DiscoveryResult.candidate_table`)."""
    if row["score"] != row["score"]:  # not scored (screen="coverage")
        return ""
    return f"{row['score']:.3g} ({row['score df']}), rank {row['rank']}"


def _main_text(row: dict) -> str:
    """A candidate's fitted main value with its unit and interval, as text ("" when not
    refit)."""
    if row["main"] != row["main"]:
        return ""
    from ..report.html_report import value_text

    u = row["main unit"]
    unit = "" if u in ("", "-") else f" {_unit_text(u)}"
    iv = row["interval"]
    return (value_text(row["main"], u) + unit
            + ("" if iv is None else f" [{value_text(iv[0], u, 3)}, {value_text(iv[1], u, 3)}]"))


def _candidate_markdown(rows: list[dict]) -> list[str]:
    """The Markdown table of the candidates of one step (rows of
    :meth:`dtwin.identify.discover.DiscoveryResult.candidate_table`)."""
    out = ["| candidate | group | coverage | score (df), rank | p | search's gap (dB) "
           "| identified | fitted main value [interval] | outcome: why |",
           "|---|---|---|---|---|---|---|---|---|"]
    out += [f"| {r['candidate']} | {r['group']} | {r['coverage']:.2f} | {_score(r)} | "
            f"{r['p-value']:.3g} | {r['gap with it (dB)']:.2f} | {r['identified']} | "
            f"{_main_text(r)} | {r['outcome']}: {r['why']} |" for r in rows]
    return out


def screen_summary(result) -> list[str]:
    """The lines ``dtwin discover`` prints on the terminal at the end of a search (a
    :class:`dtwin.identify.discover.DiscoveryResult`): the held-out gap of the base model, one
    line per step, what each added, the respecialised steps, each refit candidate's verdict
    (identified or not, accepted or set aside and why: the rows of
    :meth:`~dtwin.identify.discover.DiscoveryResult.candidate_table`, which the JSON and both
    reports print too), the candidates screened out, why the search stopped and the
    unexplained lines."""
    from ..report.html_report import value_text

    out = [f"base model: held-out gap {result.initial_gap.total:.2f} dB"]
    for s in result.steps:
        out.append(f"step {s.number}: {s.named:28s} gap {_total(s.heldout_before):>6s} → "
                   f"{_total(s.heldout_after):>6s} dB  p={s.p_value:.2g}  {s.main['name']} "
                   f"{value_text(s.main['value'], s.main['unit'], 3)}"
                   + ("" if s.main['unit'] in ("1", "", "-") else f" {s.main['unit']}")
                   + _interval_text(s.main)
                   + (" (dimensionless)" if s.main['unit'] == "1" else "")
                   + (f" (if {s.effect})" if s.named != s.effect else ""))
    for s in result.steps:
        if s.summary:
            out.append(f"step {s.number}: {s.summary}")
        if s.depth is not None:
            out.append(f"step {s.number}: depth (as `dtwin severity` fits it): "
                       f"{s.depth['summary']}")
    for k in result.respecialised:
        out.append(f"before step {k}: candidates specialised again from the current "
                   "model's residual")
    rows = result.candidate_table()
    for r in rows:
        if r["why"].startswith("screened out"):
            continue
        out.append(f"step {r['step']} candidate {r['candidate']}: identified "
                   f"{r['identified']}; {r['outcome']}: {r['why']}")
    screened: dict[int, list[str]] = {}
    for r in rows:
        if r["why"].startswith("screened out"):
            screened.setdefault(r["step"], []).append(r["candidate"])
    for k, names in screened.items():
        out.append(f"step {k}: screened out (not refit): {', '.join(names)}")
    out.append(f"stopped: {result.stop_reason}")
    out += [f"unexplained: {r.frequency:9.2f} Hz  +{r.excess_db:5.1f} dB  {r.text}"
            + _below(r, result) for r in result.unexplained[:15]]
    return out


def _below(r, result) -> str:
    """" (below the scored band …)" for a line under the lowest knot of the calibrated sensor
    response (:attr:`~dtwin.identify.discover.DiscoveryResult.scored_from`), else ""."""
    if r.frequency >= result.scored_from:
        return ""
    return (f"  (below the scored band from {result.scored_from:.2f} Hz = 0.8 N fc: listed, "
            "not scored)")


def _label_frequencies(kin) -> dict:
    """The gearbox's frequencies by name (Hz) that the legend of the line-label symbols shows
    beside each symbol: :meth:`dtwin.model.kinematics.Kinematics.as_dict` and the motor's electrical
    frequency ``f_electrical`` (None without a motor line)."""
    return {**kin.as_dict(), "f_electrical": kin.f_electrical}


def _total(g) -> str:
    """A gap's total (dB) as text; "—" where a result predates the reported gap."""
    return "—" if g is None else f"{g.total:.2f}"


def _gap_rule(settings) -> str:
    """Which bins the reported held-out gap counts, in words."""
    if settings.gap_threshold_db is None:
        return ("bins where the record or the model stands over the height that noise alone "
                "reaches with probability 1 % in the band, as calibration's gap")
    return f"bins {settings.gap_threshold_db:g} dB over the floor"


def markdown_report(result, record_name: str) -> str:
    """The readable report (Markdown) of a :class:`dtwin.identify.discover.DiscoveryResult`;
    frequencies (values in Hz) in full (:func:`dtwin.report.html_report.value_text`), other values
    with four significant digits."""
    from ..report.html_report import symbol_legend_markdown, value_text

    out = [f"# Discrepancy discovery: {record_name}", "",
           f"Input speed {result.f_sun:.4f} Hz (from the data); fm {result.kinematics.f_mesh:.2f} "
           f"Hz, fc {result.kinematics.f_carrier:.3f} Hz. Family-wise level per step "
           f"{result.settings.alpha:g} (Bonferroni over the candidates "
           f"{'scored' if result.settings.screen == 'score' else 'refit'}). "
           f"Chance that a "
           f"random tone matches some kinematic combination at this resolution and order bound: "
           f"{100 * result.chance_match_probability:.1f} %.", "",
           f"Held-out gap of the base model: **{result.initial_gap.total:.2f} dB**; final: "
           f"**{result.final_gap.total:.2f} dB** ({_gap_rule(result.settings)}). Stopped: "
           f"{result.stop_reason}.", "",
           "![gap](gap.png)", "", "![base](spectrum_step0.png)", ""]
    rows = result.candidate_table()
    for s in result.steps:
        out += [f"## Step {s.number}: {s.named}", "",
                "- before this step the candidates were specialised again from the current "
                "model's residual and its responses linearised about it"
                if s.number in result.respecialised else "",
                f"- what: {s.summary}" if s.summary else "",
                f"- depth, fitted as `dtwin severity` fits it: {s.depth['summary']}"
                if s.depth is not None else "",
                f"- effect fitted: `{s.effect}` (group `{s.group}`"
                + (f"; not told apart from {', '.join(s.indistinguishable_from)}"
                   if s.indistinguishable_from else "") + ")",
                f"- why: residual lines {_fmt_lines(s.matched_lines)}"
                + (f"; on the effect's signature: {', '.join(sorted(set(filter(None, s.matched_labels)))[:8])}"
                   if any(s.matched_labels) else ""),
                f"- held-out gap {_total(s.heldout_before)} → {_total(s.heldout_after)} dB; "
                f"the search's (bins {result.settings.threshold_db:g} dB over the floor) "
                f"{s.gap_before.total:.2f} → {s.gap_after.total:.2f} dB (full model confirmed: "
                f"{s.gap_confirmed.total:.2f} dB); p = {s.p_value:.2g} ≤ {s.level:.2g}",
                f"- {s.main['name']}: {value_text(s.main['value'], s.main['unit'])} "
                f"{_unit_text(s.main['unit'])},"
                f"{_interval_text(s.main, ' 99 % interval')} (typical on real "
                f"machines {s.main['typical_range'][0]:g}–{s.main['typical_range'][1]:g}: "
                f"{s.main['typical_note']})"
                + (f"; the group is named, not the member: these are `{s.effect}`'s values if "
                   f"it is the effect, and its interval is that fit's alone"
                   if s.named != s.effect else ""), "",
                "| parameter | value | 99 % interval | unit |", "|---|---|---|---|"]
        for p in s.parameters:
            u = p["unit"]
            out.append(f"| {p['name']} | {value_text(p['value'], u)} | "
                       f"[{value_text(p['interval'][0], u, 3)}, "
                       f"{value_text(p['interval'][1], u, 3)}] | {_unit_text(u)} |")
        out += [""] + _candidate_markdown([r for r in rows if r["step"] == s.number])
        out += ["", f"![step {s.number}](spectrum_step{s.number}.png)", ""]
    last = [r for r in rows if r["step"] > len(result.steps)]
    if last:
        out += ["## Candidates refit in the last step (none kept)", ""]
        out += _candidate_markdown(last) + [""]
    fams = list(result.combs) + ([result.modulation] if result.modulation is not None else [])
    if fams:
        out += ["## Line families in the last residual (scored as a whole)", ""]
        out += [f"- {c.text}" for c in fams] + [""]
    out += ["## Unexplained lines", ""]
    if result.scored_from > 0:
        out += [f"The gap and the search score lines from {result.scored_from:.2f} Hz (0.8 N "
                "fc, the lowest knot of the calibrated sensor response) up to the DAQ's pass "
                "band; lines outside are listed, not scored.", ""]
    if result.unexplained:
        out += ["| f (Hz) | excess (dB) | over floor (dB) | kinematic description |",
                "|---|---|---|---|"]
        out += [f"| {r.frequency:.2f} | {r.excess_db:.1f} | {r.above_floor_db:.1f} | {r.text}"
                f"{_below(r, result)} |" for r in result.unexplained]
    else:
        out.append("None.")
    if result.extra_in_model:
        out += ["", "Lines in the model but not in the measurement: "
                + _fmt_lines(result.extra_in_model, 20)]
    legend = symbol_legend_markdown(out, _label_frequencies(result.kinematics))
    if legend:
        out += ["", "## Symbols of the line labels", "", legend]
    return "\n".join(out) + "\n"


#: Most bootstrap draws `--n-boot` accepts: the p-value's Monte Carlo error is then below 0.001
#: at p = 0.05, and each draw is one refit.
MAX_N_BOOT = 100_000


@app.command()
def discover(
    record_file: Path = typer.Argument(..., help="Record file (any supported format)."),
    spec: Path | None = opts.spec_option(),
    preset: str | None = opts.preset_option(),
    kind: str | None = typer.Option(None, "--kind", help="Base model: torsional/translational "
                                                         "(default: the spec's model.kind)."),
    channel: str = typer.Option("0", "--channel", help="Channel name or index."),
    f_sun: float | None = opts.f_sun_option(),
    tacho: str | None = opts.tacho_option(),
    sample_rate: float | None = typer.Option(None, "--sample-rate",
                                             help="Sampling rate (Hz) for formats without one."),
    max_steps: int = typer.Option(3, "--max-steps", parser=opts.whole_number,
                                  help="Budget of effects added."),
    alpha: float = typer.Option(0.01, "--alpha", help="Family-wise level per step (<= 0.01)."),
    n_boot: int = typer.Option(400, "--n-boot", parser=opts.whole_number,
                               help="Bootstrap draws of the null statistic."),
    seed: int = typer.Option(0, "--seed", parser=opts.whole_number,
                             help="Seed of the bootstrap."),
    json_out: bool = typer.Option(False, "--json", help="Print the result as JSON on stdout."),
    depth: bool = typer.Option(
        True, "--depth/--no-depth",
        help="For a local tooth fault named, fit its depth as `dtwin severity` does (same "
             "twin, calibration split and bands: the same number) and report it with its "
             "95 % interval; one severity fit more."),
    out: Path | None = typer.Option(None, "--out", help="Write discover.json/.md, PNGs."),
    force: bool = typer.Option(False, "--force", help="Overwrite results in --out."),
) -> None:
    """Find where twin and measurement disagree, name the missing effect, add it, refit."""
    from dtwin.identify.discover import DiscoverySettings, fault_depths
    from dtwin.identify.discover import discover as run

    from ..io.output import to_jsonable

    opts.choice("--kind", kind, ("torsional", "translational"))
    opts.at_least("--max-steps", max_steps, 0)
    opts.finite("--alpha", alpha)
    if not 0 < alpha <= 0.01:
        raise opts.OptionError("--alpha", f"must lie in (0, 0.01], got {alpha:g}")
    opts.count("--n-boot", n_boot, 20, MAX_N_BOOT,  # each draw is one refit of every candidate
               "the p-value's Monte Carlo error sqrt(p (1 - p) / B) is below 0.001 at p = "
               "0.05 with 1e5 draws, each draw one refit; the search raises B to K / alpha by "
               "itself")
    opts.count("--seed", seed, 0, opts.MAX_SEED)
    opts.input_speed_option("--f-sun", f_sun)
    opts.tacho_reading(tacho)
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec, why="discover needs the gearbox")
    gearbox = gb.spec
    record = opts.read_record(record_file, sample_rate, tacho)
    ch = opts.channel_token(channel)
    opts.check_channel(record, ch)
    opts.check_fit_memory(record, gearbox, record_file, command="discover")
    opts.checked_record(record, ch, gearbox, f_sun, fit=True)
    # a speed given, from the tachometer or the metadata is discovery's, once checked against
    # the record's lines (a record without this gearbox's mesh lines is refused here); else
    # discovery estimates it from the lines and weighs that against the (calibrated) spec's
    claimed = opts.check_speed_against_lines(record, gearbox, f_sun, ch, record_file)
    given = None if claimed is None else claimed.f_sun

    settings = DiscoverySettings(alpha=alpha, n_boot=n_boot, max_steps=max_steps, seed=seed)
    from .progress import progress, record_size

    with progress("discover", json_out=json_out, size=record_size(record)) as stage:
        result = run(record.channel(ch), gearbox, sample_rate=record.sample_rate, f_sun=given,
                     kind=kind, settings=settings, log=stage)
        if depth:  # the depth `dtwin severity` reports for a named tooth fault
            fault_depths(result, record, gearbox, f_sun=f_sun, channel=ch,
                         progress=stage.enabled)
    report = {"record": str(record_file), "channel": str(channel), **result.to_dict()}

    def table() -> None:
        for line in screen_summary(result):
            typer.echo(line)

    def files() -> dict:
        return discover_files(result, report, record_file, channel,
                              record.units[record.index(ch)])

    opts.emit(to_jsonable(report), json_out=json_out, table=table, out=out, force=force,
              files=files, inputs=[record_file], gearbox=gb,
              parameters={"channel": str(channel), "kind": kind, "max_steps": max_steps,
                          "alpha": alpha, "n_boot": n_boot, "seed": seed, "depth": depth})


def discover_files(result, report: dict, record_file: Path, channel, unit: str | None) -> dict:
    """The files of ``dtwin discover --out``: report JSON and Markdown, figures, the spectra
    (``spectra.csv``/``.npz``) and ``report.html``."""
    from dtwin.identify.plotting.discover import plot_gap_bars, plot_step_spectra

    out_files = {"discover.json": report,
                 "discover.md": markdown_report(result, record_file.name),
                 "gap.png": plot_gap_bars(result)}
    band = (result.kinematics.f_mesh - 12 * result.kinematics.f_carrier,
            result.kinematics.f_mesh + 12 * result.kinematics.f_carrier)
    for k in range(len(result.models)):
        out_files[f"spectrum_step{k}.png"] = plot_step_spectra(result, k, unit=unit)
        out_files[f"spectrum_step{k}_mesh.png"] = plot_step_spectra(result, k, band=band,
                                                                    unit=unit)
    from dtwin.identify.tables import discovery_candidate_rows, discovery_rows

    from ..io.export import Columns
    from ..report.html_report import HTMLReport

    cols = {"frequency": result.freqs, "measured": result.measured}
    cols.update({f"model_step{k}": m for k, m in enumerate(result.models)})
    out_files["spectra.csv"] = Columns(cols, {c: ("Hz" if c == "frequency" else unit_name(unit))
                                              for c in cols})
    figures = {"Held-out gap, step by step": "gap.png"}
    for k in range(len(result.models)):
        what = "base model" if k == 0 else f"after step {k}"
        figures[f"Measured vs {what}, full band"] = f"spectrum_step{k}.png"
        figures[f"Measured vs {what}, first mesh harmonic ± 12 fc"] = f"spectrum_step{k}_mesh.png"
    out_files["report.html"] = HTMLReport(
        title=f"dtwin discover: {record_file.name} [{channel}]",
        summary={"record": str(record_file), "channel": str(channel),
                 "input speed (Hz, from the data)": result.f_sun,
                 "held-out gap of the base model (dB)": result.initial_gap.total,
                 "final held-out gap (dB)": result.final_gap.total,
                 "stopped": result.stop_reason},
        figures=figures,
        frequencies=_label_frequencies(result.kinematics),
        tables={"Effects added (99 % intervals)": discovery_rows(result),
                "Candidates judged in each step (the search's gap, bins "
                f"{result.settings.threshold_db:g} dB over the floor; p-value against the "
                "step's family-wise level)": discovery_candidate_rows(result),
                "Residual lines each added effect matched": [
                    {"step": st.number, "effect": st.named, "frequency (Hz)": r.frequency,
                     "excess (dB)": r.excess_db, "kinematic description": r.text,
                     "on the effect's signature": lab}
                    for st in result.steps
                    for r, lab in zip(st.matched_lines, st.matched_labels
                                      or [""] * len(st.matched_lines), strict=True)],
                "Unexplained lines": [{"frequency (Hz)": r.frequency,
                                       "excess (dB)": r.excess_db,
                                       "over floor (dB)": r.above_floor_db,
                                       "kinematic description": r.text,
                                       "scored": "no: below the scored band"
                                       if r.frequency < result.scored_from else "yes"}
                                      for r in result.unexplained]})
    return out_files


def _interval_text(main: dict, label: str = "") -> str:
    """The step's interval of its main value, or, where the linearised fit left the parameter's
    range and was refitted inside it in full (no interval), why there is none."""
    from ..report.html_report import value_text

    lo, hi = main["interval"]
    if lo == lo and hi == hi:  # not NaN
        u = main.get("unit", "")
        return f"{label} [{value_text(lo, u, 3)}, {value_text(hi, u, 3)}]"
    return (" (no interval: the linearised fit left the range and was refitted inside it; "
            "`dtwin severity` gives the depth with its interval)")
