"""``dtwin simulate``: run the twin and record its sensor like a DAQ.

    dtwin simulate [--preset paper-sim|paper-bench|paper-like | --spec FILE]
                   [--fault sun:missing_tooth:0.5 ...] [--f-sun HZ] [--duration S]
                   [--discard S] [--start steady|rest] [--ramp-to HZ] [--kind translational|torsional]
                   [--sample-rate HZ] [--quantity acceleration|velocity|displacement|ring_velocity]
                   [--snr-db DB] [--seed N] [--tacho-ppr N] [--quiet] [--json] [--out DIR] [--force]

Writes into ``--out DIR``: ``record.dtwin.h5`` (dtwin's own self-describing record format, read
back by every command), ``waveform.png``, ``spectrum.png`` (450–550 Hz, numbered and labelled
peaks, as the paper's Figures 7–9), ``simulate.json`` (settings, time statistics, peak labels)
and ``manifest.json``. Without ``--out`` only the summary is shown.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import typer

from ..errors import SpecError
from .app import app


def run_simulation(
    spec,
    *,
    faults: list[str] | None = None,
    f_sun: float | None = None,
    duration: float = 4.0,
    discard: float = 0.1,
    start: str = "steady",
    ramp_to: float | None = None,
    kind: str | None = None,
    sample_rate: float | None = None,
    quantity: str | None = None,
    snr_db: float | None = None,
    seed: int = 0,
    tacho_ppr: int | None = None,
    progress: bool = False,
):
    """Simulate a spec; returns ``(record, result, settings)`` (the library behind the CLI)."""
    import equinox as eqx

    from ..build import build_twin, daq_from_spec, operating_speed
    from ..faults import parse_fault
    from ..parts.drive import DrivePart
    from ..parts.shaft import Shaft
    from ..parts.speed_source import IdealSpeedSource, SpeedProfile
    from ..simulate import simulate

    f = operating_speed(spec) if f_sun is None else float(f_sun)
    if not 0 < f <= 500:
        raise SpecError([("--f-sun", f"must be the input speed in Hz in (0, 500], got {f}")])
    flts = None if not faults else tuple(parse_fault(s) for s in faults)
    tw = build_twin(spec, kind=kind, faults=flts, start=start, f_sun=f)
    if ramp_to is not None:
        # a run-up / coast-down of the input speed over the record (ideal speed source)
        i = next(j for j, p in enumerate(tw.parts) if isinstance(p, DrivePart))
        t0 = discard if start == "steady" else 0.0
        prof = SpeedProfile.ramp(2 * math.pi * ramp_to, duration, t0, 2 * math.pi * f)
        shaft = getattr(tw.parts[i].drive, "shaft", None) or Shaft()
        tw = eqx.tree_at(lambda t: t.parts[i].drive, tw, IdealSpeedSource(prof, shaft))
    overrides: dict[str, Any] = {}
    if sample_rate is not None:
        overrides["sample_rate"] = float(sample_rate)
    if quantity is not None:
        overrides["quantity"] = quantity
    if snr_db is not None:
        overrides["snr_db"] = float(snr_db)
    if tacho_ppr is not None:
        overrides["tacho_ppr"] = int(tacho_ppr)
    daq = daq_from_spec(spec, **overrides)
    res = simulate(tw, duration=duration, f_sun=f, daq=daq, start=start, discard=discard,
                   seed=seed, progress=progress)
    settings = {
        "spec": spec.name, "faults": list(faults or []), "f_sun_hz": f, "duration_s": duration,
        "discard_s": discard, "start": start, "ramp_to_hz": ramp_to, "kind": tw.kind,
        "sample_rate_hz": daq.sample_rate, "quantity": daq.quantity, "snr_db": daq.snr_db,
        "seed": seed, "tacho_ppr": daq.tacho_ppr, "solver_steps": int(res.num_steps),
    }
    record = res.to_record(metadata={"f_sun": f, "source": "dtwin simulate", **settings})
    if daq.tacho_ppr is not None:
        import dataclasses

        record = dataclasses.replace(record, tacho_ppr=daq.tacho_ppr, tacho_shaft=daq.tacho_shaft)
    return record, res, settings


@app.command()
def simulate(
    preset: str = typer.Option(None, "--preset", help="paper-sim | paper-bench | paper-like"),
    spec_file: Path = typer.Option(None, "--spec", help="gearbox spec (TOML)", exists=True,
                                   dir_okay=False, readable=True),
    fault: list[str] = typer.Option(None, "--fault",
                                    help="LOCATION:KIND:SEVERITY[:TOOTH[:PLANET[:FLANK]]], repeatable"),
    f_sun: float = typer.Option(None, "--f-sun", help="input speed (Hz); default: the spec's"),
    duration: float = typer.Option(4.0, help="record length (s)"),
    discard: float = typer.Option(0.1, help="initial transient simulated but not recorded (s)"),
    start: str = typer.Option("steady", help="steady (start at speed) | rest (from standstill)"),
    ramp_to: float = typer.Option(None, "--ramp-to", help="run-up/coast-down to this speed (Hz)"),
    kind: str = typer.Option(None, help="translational | torsional (default: the spec's)"),
    sample_rate: float = typer.Option(None, "--sample-rate", help="DAQ rate (Hz)"),
    quantity: str = typer.Option(None, help="acceleration | velocity | displacement | ring_velocity"),
    snr_db: float = typer.Option(None, "--snr-db", help="measurement noise, SNR over the record (dB)"),
    seed: int = typer.Option(0, help="noise seed"),
    tacho_ppr: int = typer.Option(None, "--tacho-ppr", help="add a tachometer channel (pulses/rev)"),
    band: tuple[float, float] = typer.Option((450.0, 550.0), help="spectrum band (Hz)"),
    quiet: bool = typer.Option(False, "--quiet", help="no progress output"),
    as_json: bool = typer.Option(False, "--json", help="print the summary as JSON"),
    out: Path = typer.Option(None, "--out", help="write the record, figures and manifest here"),
    force: bool = typer.Option(False, "--force", help="overwrite results in --out"),
) -> None:
    """Simulate the twin and write a record (dtwin's own format) with waveform and spectrum PNGs."""
    from .cmd_spectrum import gear_frequencies, load_gearbox, spectrum_report

    spec = load_gearbox(preset, spec_file)
    if spec is None:
        raise SpecError([("--preset/--spec", "give --preset NAME or --spec FILE")])
    if start not in ("steady", "rest"):
        raise SpecError([("--start", f"must be steady or rest, got {start!r}")])
    record, res, settings = run_simulation(
        spec, faults=fault, f_sun=f_sun, duration=duration, discard=discard, start=start,
        ramp_to=ramp_to, kind=kind, sample_rate=sample_rate, quantity=quantity, snr_db=snr_db,
        seed=seed, tacho_ppr=tacho_ppr, progress=not (quiet or as_json),
    )
    freqs = gear_frequencies(spec, settings["f_sun_hz"])
    nyq = record.sample_rate / 2
    bnd = (min(band[0], nyq * 0.99), min(band[1], nyq))
    report, data = spectrum_report(record, band=bnd, frequencies=freqs,
                                   n_planets=spec["gears"]["n_planets"])
    summary = {"settings": settings, "spectrum": report}
    if out is not None:
        from ..io.output import OutputFolder
        from ..io.readers import write_record
        from ..plotting.spectrum import plot_spectrum_peaks, plot_waveform

        folder = OutputFolder(out, force=force, spec=_spec_dict(spec), seed=seed,
                              parameters=settings)
        folder.write_with("record.dtwin.h5", lambda p: write_record(record, p, force=True))
        unit = record.units[0]
        folder.savefig("waveform.png", plot_waveform(data["t"], data["x"], unit=unit,
                                                     title=f"Simulated waveform — {spec.name}"))
        folder.savefig("spectrum.png", plot_spectrum_peaks(
            data["freqs"], data["spec"], data["labelled"], band=bnd, unit=unit,
            floor=data["floor"], title=f"Simulated spectrum — {spec.name} "
                                       f"{', '.join(fault or []) or 'healthy'}"))
        folder.write_json("simulate.json", summary)
    if as_json:
        from ..io.output import to_jsonable

        typer.echo(json.dumps(to_jsonable(summary), indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"dtwin simulate — {spec.name}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for k, v in settings.items():
        table.add_row(k, str(v))
    st = report["time_stats"]
    table.add_row("RMS", f"{st['rms']:.4g} {record.units[0]}")
    table.add_row("kurtosis", f"{st['kurtosis']:.3f}")
    table.add_row("peaks labelled", "; ".join(
        f"{p['number']}: {p['frequency_hz']:.1f} Hz {p['labels'][0] if p['labels'] else '?'}"
        for p in report["peaks"][:8]))
    if out is not None:
        table.add_row("written to", str(out))
    Console().print(table)


def _spec_dict(spec) -> dict:
    from ..spec import spec_to_dict

    return spec_to_dict(spec)
