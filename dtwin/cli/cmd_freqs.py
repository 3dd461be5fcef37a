"""``dtwin freqs``: characteristic frequencies of a planetary gearbox.

    dtwin freqs --preset paper-sim|paper-bench|lin-parker | --spec FILE [--f-sun HZ]
                [--planet-fault paper|both_flanks] [--json] [--out DIR] [--force]

The input speed is the spec's ``operating.f_sun`` unless ``--f-sun`` (Hz) is given. A table on
the terminal lists the frequencies under their registry names (``f_sun``, ``f_carrier``,
``f_mesh``, ``f_sun_fault``, ``f_planet_fault``, ``f_ring_fault``, ``f_planet_pass``,
``f_planet``), in Hz and as orders of the input speed, with the geometry they follow from;
``--json`` prints the same as JSON on stdout (nothing else); ``--out DIR`` writes
``freqs.json`` and ``manifest.json``. See :func:`dtwin.model.gears.characteristic_frequencies`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from ..report.analyses import freqs_report
from . import options as opts
from .app import app

_MEANING = {
    "f_sun": "sun (input) rotation, the paper's f_sr",
    "f_carrier": "carrier (output) rotation",
    "f_mesh": "gear mesh frequency",
    "f_sun_fault": "sun local fault, f_mesh N / Zs (paper's f_s)",
    "f_planet_fault": "planet local fault",
    "f_ring_fault": "ring local fault, f_mesh N / Zr",
    "f_planet_pass": "planet pass, N f_carrier",
    "f_planet": "planet spin relative to the carrier",
}



@app.command()
def freqs(
    preset: str | None = opts.preset_option(),
    spec: Path | None = opts.spec_option(),
    f_sun: float | None = typer.Option(
        None, "--f-sun", help="Input (sun) speed in Hz; default: the spec's operating.f_sun."),
    planet_fault: str = typer.Option(
        "paper", "--planet-fault", help="paper (f_mesh/Zp) or both_flanks (2 f_mesh/Zp)."),
    json_out: bool = opts.json_option(),
    out: Path | None = opts.out_option("freqs.json, freqs.csv/.npz"),
    force: bool = opts.force_option(),
) -> None:
    """Characteristic frequencies (mesh, carrier, fault, planet pass) of a gearbox."""
    opts.choice("--planet-fault", planet_fault, ("paper", "both_flanks"))
    opts.input_speed_option("--f-sun", f_sun)
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec)  # geometry warnings go to stderr
    report = freqs_report(gb.spec, f_sun, planet_fault, gb.source)
    opts.emit(report, json_out=json_out, table=lambda: _print_table(report), out=out,
              force=force, files=_files(report), gearbox=gb,
              parameters={"source": gb.source, "f_sun": report["f_sun_hz"],
                          "planet_fault": planet_fault})


def _files(report: dict[str, Any]) -> dict[str, Any]:
    """freqs.json and the frequencies as freqs.csv/.npz (name, Hz, order of the input speed)."""
    from ..io.export import Columns

    names = list(report["frequencies_hz"])
    return {"freqs.json": report,
            "freqs.csv": Columns({"name": names,
                                  "frequency": [report["frequencies_hz"][n] for n in names],
                                  "order": [report["orders"][n] for n in names]},
                                 {"name": None, "frequency": "Hz", "order": "1"})}


def _print_table(report: dict[str, Any]) -> None:
    from rich.table import Table

    g = report["gears"]
    geo = report["geometry"]
    title = (f"{report['source']}: Zs/Zp/Zr = {g['z_sun']}/{g['z_planet']}/{g['z_ring']}, "
             f"N = {g['n_planets']}, f_sun = {report['f_sun_hz']:g} Hz "
             f"({60 * report['f_sun_hz']:g} rpm)")
    table = Table(title=title)
    table.add_column("name")
    table.add_column("f (Hz)", justify="right")
    table.add_column("order", justify="right")
    table.add_column("meaning")
    for name, v in report["frequencies_hz"].items():
        meaning = _MEANING[name]
        if name == "f_planet_fault":
            meaning += (" (paper: f_mesh/Zp)" if report["planet_fault"] == "paper"
                        else " (both flanks: 2 f_mesh/Zp)")
        table.add_row(name, f"{v:.3f}", f"{report['orders'][name]:.4f}", meaning)
    console = opts.console()
    opts.print_table(table)
    console.print(
        f"a = {geo['centre_distance'] * 1e3:.3f} mm, x = ({geo['x_sun']:.4f}, "
        f"{geo['x_planet']:.4f}, {geo['x_ring']:.4f}), α_sp = "
        f"{geo['alpha_sp'] * 57.29577951308232:.2f}°, α_rp = "
        f"{geo['alpha_rp'] * 57.29577951308232:.2f}°, ε_sp = {geo['eps_sp']:.3f}, ε_rp = "
        f"{geo['eps_rp']:.3f}, phase0_rp − phase0_sp = {geo['phase0_rp']:.4f} cycles; "
        f"2 f_mesh/Zp = {report['f_planet_fault_both_flanks_hz']:.3f} Hz"
    )
