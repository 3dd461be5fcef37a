"""``dtwin modes``: natural frequencies, mode types and mesh-stiffness sensitivities of a gearbox.

    dtwin modes --preset paper-sim|paper-bench|lin-parker | --spec FILE
                [--model translational|torsional] [--planets N] [--json] [--out DIR] [--force]

Table on the terminal (one row per distinct frequency: Hz, Lin & Parker type, multiplicity,
relative sensitivities ``(k/f) df/dk`` to the sun–planet and ring–planet mesh stiffness, and the
frequency in mesh orders when the gearbox's operating speed is known); ``--json`` prints the
same as JSON on stdout; ``--out DIR`` writes ``modes.json``, ``modes.png``, the distinct
modes as ``modes.csv`` and ``modes.npz`` (named columns with units) and ``manifest.json``. ``lin-parker`` is Lin & Parker's (1999) example
(``dtwin/spec/presets/lin-parker.toml``); ``--planets N`` replaces the preset's or spec's number of
planets (equally spaced), e.g. Lin & Parker's N = 4 and 5 cases.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from ..report.analyses import modes_report, operating_mesh_frequency
from . import options as opts
from .app import app


@app.command()
def modes(
    preset: str | None = opts.preset_option(),
    spec: Path | None = opts.spec_option(),
    model: str = typer.Option(
        "translational", "--model", help="translational (Lin & Parker, 3 DOF per body) or "
        "torsional (rotations only)."),
    planets: int | None = typer.Option(
        None, "--planets", help="Override the number of planets (equally spaced)."),
    json_out: bool = opts.json_option(),
    out: Path | None = opts.out_option("modes.json, modes.png, modes.csv/.npz"),
    force: bool = opts.force_option(),
) -> None:
    """Natural frequencies and Lin & Parker mode types at mean mesh stiffness."""
    from ..model.modal import MODELS

    opts.choice("--model", model, tuple(MODELS))
    opts.at_least("--planets", planets, 1)
    if planets is not None and planets > 12:
        raise opts.OptionError("--planets", f"at most 12 planets, got {planets}")
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec, planets=planets)
    lp, spec_obj, source = gb.lumped(), gb.spec, gb.source
    f_mesh = operating_mesh_frequency(spec_obj, lp)
    sample_rate = spec_obj["sensor"].get("sample_rate")
    report, res = modes_report(lp, model, f_mesh)
    report["source"] = source

    def files() -> dict:
        from ..io.export import Columns
        from ..plotting.modes import plot_modes

        rows = report["modes"]
        cols = {"frequency": [r["frequency_hz"] for r in rows],
                "multiplicity": [r["multiplicity"] for r in rows],
                "sensitivity_k_sun_planet": [r["sensitivity_k_sun_planet"] for r in rows],
                "sensitivity_k_ring_planet": [r["sensitivity_k_ring_planet"] for r in rows]}
        units = {"frequency": "Hz", "multiplicity": "1", "sensitivity_k_sun_planet": "Hz/(N/m)",
                 "sensitivity_k_ring_planet": "Hz/(N/m)"}
        return {"modes.json": report,
                "modes.png": plot_modes(res, f_mesh=f_mesh, sample_rate=sample_rate,
                                        title=f"{source}: natural frequencies, {model} model"),
                "modes.csv": Columns(cols, units)}

    opts.emit(report, json_out=json_out, table=lambda: _print_table(report), out=out,
              force=force, files=files, gearbox=gb,
              parameters={"model": model, "source": source, "n_planets": lp.n_planets})


def _print_table(report: dict[str, Any]) -> None:
    from rich.table import Table

    mesh = report["f_mesh_hz"]
    title = (f"{report['source']}: {report['model']} model, N = {report['n_planets']}"
             + (f", f_mesh = {mesh:.1f} Hz" if mesh else ""))
    table = Table(title=title)
    table.add_column("f (Hz)", justify="right")
    table.add_column("type")
    table.add_column("mult.", justify="right")
    table.add_column("(k/f) df/dk sun-planet", justify="right")
    table.add_column("(k/f) df/dk ring-planet", justify="right")
    if mesh:
        table.add_column("f / f_mesh", justify="right")
    for r in report["modes"]:
        cells = [f"{r['frequency_hz']:.1f}", r["type"], str(r["multiplicity"]),
                 f"{r['sensitivity_k_sun_planet']:.3f}", f"{r['sensitivity_k_ring_planet']:.3f}"]
        if mesh:
            cells.append(f"{r['mesh_order']:.2f}")
        table.add_row(*cells)
    opts.print_table(table)
