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

import json
import math
from pathlib import Path
from typing import Any

import typer

from ..errors import SpecError
from .app import app


def load_gearbox(preset: str | None, spec_file: Path | None, planets: int | None):
    """Lumped parameters, the validated spec and a source label for the CLI's gearbox options.

    ``--planets N`` replaces ``gears.n_planets`` of the preset or spec (equally spaced planets),
    so that the geometry checks of :mod:`dtwin.gears` still apply (tip circles that overlap are
    refused).
    """
    from .. import spec as spec_mod

    if (preset is None) == (spec_file is None):
        raise SpecError([("--preset/--spec", "give exactly one of --preset NAME or --spec FILE")])
    if preset is not None:
        spec = spec_mod.preset(preset)
        source = preset
    else:
        spec = spec_mod.load_spec(spec_file)
        source = str(spec_file)
    if planets is not None:
        if planets < 1:
            raise SpecError([("--planets", f"must be >= 1, got {planets}")])
        data = spec_mod.spec_to_dict(spec)
        data.pop("source", None)
        data["gears"]["n_planets"] = planets
        data.get("imperfections", {}).pop("planet_position_errors", None)
        spec = spec_mod.load_spec(data)
    return spec_mod.lumped_from_spec(spec), spec, source


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
    preset: str | None = typer.Option(
        None, "--preset", help="paper-sim, paper-bench or lin-parker (Lin & Parker 1999)."),
    spec: Path | None = typer.Option(None, "--spec", help="Gearbox spec file (TOML)."),
    model: str = typer.Option(
        "translational", "--model", help="translational (Lin & Parker, 3 DOF per body) or "
        "torsional (rotations only)."),
    planets: int | None = typer.Option(
        None, "--planets", help="Override the number of planets (equally spaced)."),
    json_out: bool = typer.Option(False, "--json", help="Print results as JSON on stdout."),
    out: Path | None = typer.Option(
        None, "--out", help="Write modes.json, modes.png and manifest.json into this folder."),
    force: bool = typer.Option(False, "--force", help="Overwrite results in --out."),
) -> None:
    """Natural frequencies and Lin & Parker mode types at mean mesh stiffness."""
    from ..modal import MODELS

    if model not in MODELS:
        raise SpecError([("--model", f"unknown model {model!r}; use translational or torsional")])
    lp, spec_obj, source = load_gearbox(preset, spec, planets)
    f_mesh = _mesh_frequency(spec_obj, lp)
    sample_rate = spec_obj["sensor"].get("sample_rate")
    report, res = modes_report(lp, model, f_mesh)
    report["source"] = source
    if json_out:
        typer.echo(json.dumps(report, indent=2))
    else:
        _print_table(report)
    if out is not None:
        from ..io.output import OutputFolder
        from ..plotting.modes import plot_modes
        from ..spec import spec_to_dict

        folder = OutputFolder(
            out, force=force, inputs=[spec] if spec is not None else [],
            spec=spec_to_dict(spec_obj),
            parameters={"model": model, "source": source, "n_planets": lp.n_planets},
        )
        folder.write_json("modes.json", report)
        fig = plot_modes(res, f_mesh=f_mesh, sample_rate=sample_rate, title=f"{source}: natural frequencies, {model} model")
        folder.savefig("modes.png", fig)
        import matplotlib.pyplot as plt

        plt.close(fig)
        if not json_out:
            typer.echo(f"wrote {folder.path}/modes.json, modes.png, manifest.json", err=True)


def _print_table(report: dict[str, Any]) -> None:
    from rich.console import Console
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
    Console().print(table)
