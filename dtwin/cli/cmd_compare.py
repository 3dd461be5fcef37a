"""``dtwin compare-drives``: the paper's Figure 15, traditional model versus motor-coupled twin.

    dtwin compare-drives [--preset paper-sim | --spec FILE] [--severities 0,0.25,0.5,0.75,1]
                         [--duration S] [--discard S] [--kind translational|torsional]
                         [--quantity acceleration|velocity|...] [--k-shaft NM_PER_RAD]
                         [--speed-bandwidth HZ] [--no-sensitivity] [--sweep]
                         [--json] [--out DIR] [--force]

For each sun missing-tooth severity: RMS of the sensor signal over a steady window for the
traditional model (ideal speed source) and the twin with the PMSM drive, and ``dRMS/dseverity``
by forward-mode autodiff (:mod:`dtwin.report.drive_comparison`). ``--sweep`` adds the sensitivity at severity
0.5 versus shaft stiffness and speed-loop bandwidth. Writes into ``--out DIR``:
``comparison.png`` (Figure 15 side by side), ``sensitivity.png``, ``sweep.png`` (with
``--sweep``), ``compare_drives.json`` and ``manifest.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from ..errors import SpecError
from . import options as opts
from .app import app

_QUANTITIES = ("acceleration", "velocity", "displacement", "ring_velocity")


def _parse_list(text: str, name: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise SpecError([(name, f"expected comma-separated numbers, got {text!r}")]) from None
    if not vals:
        raise SpecError([(name, "give at least one value")])
    return vals


#: The comparison's peak over :func:`dtwin.simulation.memory.simulation_bytes` per simulation: XLA asked
#: for 984 GB in one allocation for 5 severities × 3000.1 s with sensitivities, where the
#: estimate gives 749 GB (1.31×: the coupled drive's states and the solver's stages); rounded up.
COMPARE_OVERHEAD = 2.0


def _check_memory(spec, daq, n_severities: int, span: float, sensitivity: bool) -> None:
    """Refuse a comparison that would not fit in the memory available (:mod:`dtwin.simulation.memory`):
    each model simulates every severity at once (one compiled call), the translational twin's
    state plus the drive's saved at the DAQ's oversampled rate, twice with the sensitivity's
    tangents (issue 53: ``--duration 3000`` asked XLA for 984 GB, an internal error)."""
    from ..simulation.memory import require, simulation_bytes

    n_dof = 3 * (int(spec["gears"]["n_planets"]) + 3) + 4
    copies = n_severities * (2 if sensitivity else 1)
    need = COMPARE_OVERHEAD * copies * simulation_bytes(span, daq.sample_rate, n_dof,
                                                       oversample=daq.oversample)
    require(need, what=f"{n_severities} severities × {span:g} s at {daq.sample_rate:g} Hz "
            f"(simulated at once, {daq.oversample} × that rate"
            + (", with their sensitivities)" if sensitivity else ")"), option="--duration",
            fix="lower --duration (the RMS settles within a second) or pass fewer --severities")


@app.command("compare-drives")
def compare_drives_cmd(
    preset: str = opts.preset_option(),
    spec_file: Path = opts.spec_option(),

    severities: str = typer.Option("0,0.25,0.5,0.75,1", "--severities",
                                   help="sun missing-tooth severities in [0, 1], comma-separated"),
    duration: float = typer.Option(0.5, help="steady window for the RMS (s)"),
    discard: float = typer.Option(0.1, help="transient simulated before the window (s)"),
    kind: str = typer.Option(None, help="translational | torsional (default: the spec's)"),
    quantity: str = typer.Option(None, help="acceleration | velocity | displacement | "
                                            "ring_velocity (default: the spec's sensor)"),
    k_shaft: float = typer.Option(None, "--k-shaft", help="shaft stiffness (N·m/rad)"),
    speed_bandwidth: float = typer.Option(None, "--speed-bandwidth",
                                          help="PMSM speed-loop bandwidth (Hz)"),
    no_sensitivity: bool = typer.Option(False, "--no-sensitivity",
                                        help="skip dRMS/dseverity (faster)"),
    sweep: bool = typer.Option(False, "--sweep", help="also sweep k_shaft and the bandwidth"),
    as_json: bool = typer.Option(False, "--json", help="print the results as JSON"),
    out: Path = typer.Option(None, "--out", help="write figures, JSON and manifest here"),
    force: bool = typer.Option(False, "--force", help="overwrite results in --out"),
) -> None:
    """RMS vs sun-fault severity: traditional model (ideal speed source) vs PMSM-coupled twin."""
    from ..report.drive_comparison import MODELS, compare_drives, sensitivity_sweep
    from ..spec.build import daq_from_spec
    sev = _parse_list(severities, "--severities")
    for s in sev:
        opts.in_range("--severities", s, 0.0, 1.0, "(a severity)")
    opts.simulated_span(duration, discard)
    opts.choice("--kind", kind, ("translational", "torsional"))
    opts.choice("--quantity", quantity, _QUANTITIES)
    opts.positive("--k-shaft", k_shaft, unit="N·m/rad")
    opts.positive("--speed-bandwidth", speed_bandwidth, unit="Hz")
    opts.check_out(out, force)  # refuse an existing result before minutes of simulation
    gb = opts.load_gearbox(preset, spec_file)
    spec = gb.spec
    daq = daq_from_spec(spec, **({"quantity": quantity} if quantity else {}))
    _check_memory(spec, daq, len(sev), duration + discard, not no_sensitivity)
    parameters = {
        "severities": sev, "duration_s": duration, "discard_s": discard, "kind": kind,
        "quantity": daq.quantity, "k_shaft": k_shaft, "speed_bandwidth_hz": speed_bandwidth,
        "sensitivity": not no_sensitivity, "sweep": sweep}
    from .logs import note

    note(f"simulating both models at {len(sev)} severities ({duration:g} s each, one compiled "
         "call per model; minutes on a CPU) …")
    with opts.working("simulating"):
        cmp = compare_drives(spec, sev, kind=kind, duration=duration, discard=discard, daq=daq,
                             sensitivity=not no_sensitivity, k_shaft=k_shaft,
                             speed_bandwidth=speed_bandwidth)
    summary = {"comparison": cmp.to_dict()}
    swp = None
    if sweep:
        note("sensitivity sweep over shaft stiffness and speed-loop bandwidth …")
        with opts.working("sweeping"):
            swp = sensitivity_sweep(spec, kind=kind, duration=duration, discard=discard,
                                    daq=daq)

        summary["sweep"] = swp.to_dict()
    if out is not None:
        from ..io.output import OutputFolder
        from ..report.drive_comparison_figures import (
            plot_drive_comparison,
            plot_sensitivity,
            plot_sensitivity_sweep,
        )

        with OutputFolder(out, force=force, spec=gb.spec_dict(), staged=True,
                          parameters=parameters) as folder:

            folder.set("settings", cmp.settings)
            folder.savefig("comparison.png", plot_drive_comparison(cmp))
            if cmp.slope is not None:
                folder.savefig("sensitivity.png", plot_sensitivity(cmp))
            if swp is not None:
                folder.savefig("sweep.png", plot_sensitivity_sweep(swp))
            folder.write_json("compare_drives.json", summary)
            from ..io.export import write_columns

            cols = {"severity": cmp.severities,
                    **{f"rms_{m}": cmp.rms[m] for m in MODELS},
                    **({f"slope_{m}": cmp.slope[m] for m in MODELS} if cmp.slope else {})}
            write_columns(folder, "compare_drives", cols,
                          {k: ("1" if k == "severity" else cmp.unit if k.startswith("rms")
                               else f"{cmp.unit} per unit severity") for k in cols})
    if as_json:
        from ..io.output import to_jsonable

        typer.echo(json.dumps(to_jsonable(summary), indent=2))
        return
    from rich.table import Table

    table = Table(title=f"dtwin compare-drives — {spec.name}, {cmp.settings['kind']}, "
                        f"RMS of {cmp.settings['quantity']} ({cmp.unit})")
    table.add_column("severity", justify="right")
    for m in MODELS:
        table.add_column(f"RMS {m}", justify="right")
        table.add_column(f"rise {m}", justify="right")
        if cmp.slope is not None:
            table.add_column(f"dRMS/ds {m}", justify="right")
    for row in cmp.rows():
        cells = [f"{row['severity']:g}"]
        for m in MODELS:
            cells += [f"{row[f'rms_{m}']:.5g}", f"{100 * row[f'rise_{m}']:+.2f} %"]
            if cmp.slope is not None:
                cells.append(f"{row[f'slope_{m}']:.4g}")
        table.add_row(*cells)
    d = cmp.to_dict()
    table.caption = (f"secant slope traditional {d['secant_slope']['traditional']:.4g}, coupled "
                     f"{d['secant_slope']['coupled']:.4g} {cmp.unit}/severity (ratio "
                     f"{d['secant_slope_ratio']:.4f})" + (f"; written to {out}" if out else ""))
    opts.print_table(table)
