"""``dtwin stiffness``: the mesh-stiffness waveform of a gearbox, with and without faults.

    dtwin stiffness --preset paper-sim|paper-bench | --spec FILE
                    [--fault LOCATION:KIND:SEVERITY[:TOOTH[:PLANET[:FLANK]]] ...]
                    [--planet P] [--cycles C] [--json] [--out DIR] [--force]

Shows planet 0's (``--planet``; default the first planet fault's planet) sun–planet and
ring–planet mesh stiffness under rigid kinematics (ring fixed)
over a span of mesh cycles: one relative sun revolution (``Zs`` cycles) for a healthy gearbox or
a sun fault, ``Zp`` for a planet fault and ``Zr`` for a ring fault, unless ``--cycles`` says.
Faults come from ``--fault`` (repeatable, e.g. ``--fault sun:missing_tooth:0.5``) and, if none
is given, from the spec's ``[[faults]]``. Terminal: a table of ``k_mean``, ``c'``, ``1.75 c'``,
``eps`` and, with faults, the smallest faulty stiffness of each mesh. ``--json``: the same on
stdout. ``--out DIR``: ``stiffness.json`` (with the curves), ``stiffness.png``, the curves as
``stiffness.csv`` and ``stiffness.npz`` (named columns with units), ``manifest.json``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from ..report.analyses import stiffness_curves, stiffness_report
from . import options as opts
from .app import app


@app.command()
def stiffness(
    preset: str | None = opts.preset_option(),
    spec: Path | None = opts.spec_option(),
    fault: list[str] | None = typer.Option(
        None, "--fault", help="LOCATION:KIND:SEVERITY[:TOOTH[:PLANET[:FLANK]]], e.g. "
        "sun:missing_tooth:0.5 or planet:pitting:0.3:4:1 (repeatable; kinds missing_tooth, "
        "pitting, crack). Default: the spec's [[faults]]."),
    planet: int | None = typer.Option(
        None, "--planet", help="Planet whose meshes are shown (default: that of the first planet "
        "fault, else 0)."),
    cycles: float | None = typer.Option(
        None, "--cycles", help="Mesh cycles shown (default: teeth of the faulty gear, Zs "
        "without faults)."),
    json_out: bool = opts.json_option(),
    out: Path | None = opts.out_option("stiffness.json, stiffness.png, stiffness.csv/.npz"),
    force: bool = opts.force_option(),
) -> None:
    """Mesh-stiffness waveform of planet 0's sun and ring meshes, healthy and faulty."""
    from ..model.faults import faults_from_table, parse_fault

    opts.positive("--cycles", cycles)
    if cycles is not None and cycles > 10_000:
        raise opts.OptionError("--cycles", f"at most 10000 mesh cycles, got {cycles:g}")
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec)
    spec_obj, lp, source = gb.spec, gb.lumped(), gb.source
    faults = [parse_fault(f) for f in fault] if fault else list(faults_from_table(spec_obj["faults"]))
    n_harm = int(spec_obj["mesh"].get("n_harmonics", 12))
    for f in faults:  # boundary checks (tooth, planet) before any computation
        if f.location == "planet" and f.planet >= lp.n_planets:
            raise opts.OptionError("--fault", f"planet {f.planet} does not exist; the gear set "
                                   f"has planets 0..{lp.n_planets - 1}")
    if planet is None:
        planet = next((f.planet for f in faults if f.location == "planet"), 0)
    if not 0 <= planet < lp.n_planets:
        raise opts.OptionError("--planet", f"planets are numbered 0..{lp.n_planets - 1}, got "
                               f"{planet}")
    curves = stiffness_curves(lp, faults, n_cycles=cycles, n_harmonics=n_harm, planet=planet)
    report = stiffness_report(lp, faults, curves)
    report["source"] = source
    report["planet"] = planet
    report["n_harmonics"] = n_harm

    def files() -> dict:
        import numpy as np

        from ..plotting.stiffness import plot_mesh_stiffness

        zoom = None
        if faults:
            loss = (curves["k_sun_planet"] - curves["k_sun_planet_faulty"]
                    + curves["k_ring_planet"] - curves["k_ring_planet_faulty"])
            centre = float(curves["mesh_cycles"][int(np.argmax(loss))])
            zoom = (centre - 2.5, centre + 2.5)
        fig = plot_mesh_stiffness(
            curves["mesh_cycles"], curves["k_sun_planet"], curves["k_ring_planet"],
            k_sun_planet_faulty=curves.get("k_sun_planet_faulty"),
            k_ring_planet_faulty=curves.get("k_ring_planet_faulty"),
            zoom=zoom, planet=planet, fault_label=" + ".join(r["label"] for r in report["faults"]) or "faulty",
            title=f"{source}: mesh stiffness (Zs={lp.z_sun}, Zp={lp.z_planet}, Zr={lp.z_ring})",
        )
        from ..io.export import Columns

        units = {k: ("1" if k == "mesh_cycles" else "N/m") for k in curves}
        return {"stiffness.json": {**report, "curves": curves}, "stiffness.png": fig,
                "stiffness.csv": Columns(dict(curves), units)}

    opts.emit(report, json_out=json_out, table=lambda: _print_table(report), out=out,
              force=force, files=files, gearbox=gb,
              parameters={"source": source, "fault": fault or []})


def _print_table(report: dict[str, Any]) -> None:
    from rich.table import Table

    faulty = bool(report["faults"])
    title = (f"{report['source']}: mesh stiffness of planet {report['planet']} (Zs="
             f"{report['z_sun']}, Zp={report['z_planet']}, Zr={report['z_ring']}, "
             f"N={report['n_planets']})")
    table = Table(title=title)
    table.add_column("mesh")
    table.add_column("k_mean (N/m)", justify="right")
    table.add_column("c' single (N/m)", justify="right")
    table.add_column("1.75 c' double (N/m)", justify="right")
    table.add_column("eps", justify="right")
    if faulty:
        table.add_column("min k with fault (N/m)", justify="right")
    for name, r in report["meshes"].items():
        cells = [name.replace("_", "-"), f"{r['k_mean']:.4g}", f"{r['c_single']:.4g}",
                 f"{r['c_double']:.4g}", f"{r['eps']:.3f}"]
        if faulty:
            cells.append(f"{r['k_min_faulty']:.4g}")
        table.add_row(*cells)
    console = opts.console()
    opts.print_table(table)
    for f in report["faults"]:
        console.print(f"fault: {f['label']} (severity = {f['meaning']})")
