"""``dtwin modes``: natural frequencies, mode types and mesh-stiffness sensitivities of a gearbox.

    dtwin modes --preset paper-sim|paper-bench|lin-parker | --spec FILE
                [--model translational|torsional] [--planets N] [--json] [--out DIR] [--force]

Table on the terminal (one row per distinct frequency: Hz, Lin & Parker type, multiplicity,
relative sensitivities ``(k/f) df/dk`` to the sun–planet and ring–planet mesh stiffness, and the
frequency in mesh orders when the gearbox's operating speed is known); ``--json`` prints the
same as JSON on stdout; ``--out DIR`` writes ``modes.json``, ``modes.png`` and
``manifest.json``. ``lin-parker`` is Lin & Parker's (1999) example
(``dtwin/presets/lin-parker.toml``); ``--planets N`` replaces the preset's or spec's number of
planets (equally spaced), e.g. Lin & Parker's N = 4 and 5 cases.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import typer

from . import options as opts
from .app import app


def _mesh_frequency(spec: Any, lp: Any) -> float | None:
    """f_mesh = f_sun Zs Zr / (Zs + Zr) (Hz) at the spec's operating speed, if it gives one."""
    f_sun = spec["operating"].get("f_sun")
    if f_sun is None or not math.isfinite(float(f_sun)) or float(f_sun) <= 0:
        return None
    return float(f_sun) * lp.z_sun * lp.z_ring / (lp.z_sun + lp.z_ring)


def modes_report(lp, model: str, f_mesh: float | None) -> dict[str, Any]:
    """JSON-ready summary: distinct modes with type, multiplicity, sensitivities, mesh order."""
    import numpy as np

    from ..modal import frequency_sensitivities, modal_analysis

    res = modal_analysis(lp, model)
    sens = frequency_sensitivities(lp, ("k_sun_planet", "k_ring_planet"), model)
    s_sp, s_rp = np.asarray(sens["k_sun_planet"]), np.asarray(sens["k_ring_planet"])
    rows = []
    for g in res.groups():
        j = g["modes"]
        row = {
            "frequency_hz": g["frequency"],
            "type": g["type"],
            "multiplicity": g["multiplicity"],
            "sensitivity_k_sun_planet": float(np.mean(s_sp[j])),
            "sensitivity_k_ring_planet": float(np.mean(s_rp[j])),
        }
        if f_mesh:
            row["mesh_order"] = g["frequency"] / f_mesh
        rows.append(row)
    return {
        "model": model,
        "n_planets": lp.n_planets,
        "f_mesh_hz": f_mesh,
        "modes": rows,
        "frequencies_hz": np.asarray(res.frequencies).tolist(),
        "mode_types": list(res.mode_types),
        "coordinates": list(res.coordinates),
    }, res


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
    out: Path | None = opts.out_option("modes.json, modes.png"),
    force: bool = opts.force_option(),
) -> None:
    """Natural frequencies and Lin & Parker mode types at mean mesh stiffness."""
    from ..modal import MODELS

    opts.choice("--model", model, tuple(MODELS))
    opts.at_least("--planets", planets, 1)
    if planets is not None and planets > 12:
        raise opts.OptionError("--planets", f"at most 12 planets, got {planets}")
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec, planets=planets)
    lp, spec_obj, source = gb.lumped(), gb.spec, gb.source
    f_mesh = _mesh_frequency(spec_obj, lp)
    sample_rate = spec_obj["sensor"].get("sample_rate")
    report, res = modes_report(lp, model, f_mesh)
    report["source"] = source

    def files() -> dict:
        from ..plotting.modes import plot_modes

        return {"modes.json": report,
                "modes.png": plot_modes(res, f_mesh=f_mesh, sample_rate=sample_rate,
                                        title=f"{source}: natural frequencies, {model} model")}

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
