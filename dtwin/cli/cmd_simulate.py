"""``dtwin simulate``: run the twin and record its sensor like a DAQ.

    dtwin simulate [--preset paper-sim|paper-bench|paper-like | --spec FILE]
                   [--fault sun:missing_tooth:0.5 ...] [--f-sun HZ] [--duration S]
                   [--discard S] [--start steady|rest] [--ramp-to HZ] [--kind translational|torsional]
                   [--sample-rate HZ] [--quantity acceleration|velocity|displacement|ring_velocity]
                   [--snr-db DB] [--seed N] [--tacho-ppr N] [--quiet] [--json] [--out DIR] [--force]

Writes into ``--out DIR``: ``record.dtwin.h5`` (dtwin's own self-describing record format, read
back by every command), ``waveform.png``, ``spectrum.png`` (450–550 Hz, numbered and labelled
peaks, as the paper's Figures 7–9), ``spectrum.csv``/``.npz``, ``simulate.json`` (settings,
time statistics, peak labels), ``report.html`` (the figures, settings and peaks on one page) and
``manifest.json``. Without ``--out`` only the summary is shown.
"""

from __future__ import annotations

from pathlib import Path

import typer

from ..report.analyses import gear_frequencies, run_simulation, spectrum_report
from . import options as opts
from .app import app

#: Longest start-up transient `--discard` accepts (s).
MAX_DISCARD_S = opts.MAX_DISCARD_S


def _check_memory(spec, duration: float, rate: float) -> None:
    """Refuse a record that would not fit in the memory available (:mod:`dtwin.simulation.memory`): the
    state of the translational twin (``3 (N + 3)`` degrees of freedom, the larger model) plus
    a drive's few, saved at 4 × the DAQ rate."""
    from ..simulation.memory import require, simulation_bytes

    n_dof = 3 * (int(spec["gears"]["n_planets"]) + 3) + 4
    need = simulation_bytes(duration, rate, n_dof)
    require(need, what=f"a {duration:g} s record at {rate:g} Hz ({duration * rate:.3g} samples, "
            f"the solver saving {2 * n_dof} states at 4 × that rate)", option="--sample-rate",
            fix="lower --sample-rate or --duration")


def _check_tacho(spec, ppr: int, f_sun: float | None, ramp_to: float | None,
                 rate: float) -> None:
    """Refuse more tachometer pulses per revolution than the DAQ rate resolves: `ppr` pulses
    per revolution of a shaft turning at ``f`` Hz (the highest speed of the run, on the shaft
    the spec's DAQ puts the tachometer on) make a pulse train of ``ppr f`` Hz, which must stay
    at or below Nyquist, ``rate / 2`` (Hz)."""
    from ..spec.build import daq_from_spec

    f_nom = f_sun or spec["operating"].get("f_sun")
    if not f_nom:
        return
    f_top = max(float(f_nom), float(ramp_to or 0.0))
    shaft = daq_from_spec(spec).tacho_shaft or "sun"
    f_shaft = f_top if shaft == "sun" else float(gear_frequencies(spec, f_top)["f_carrier"])
    high = max(1, int(rate / (2.0 * f_shaft)))
    opts.count("--tacho-ppr", ppr, 1, high,
               f"{ppr} pulses per revolution of the {shaft} shaft at {f_shaft:.4g} Hz make "
               f"{ppr * f_shaft:.4g} Hz, above Nyquist ({rate / 2:g} Hz at {rate:g} Hz): lower "
               "--tacho-ppr or raise --sample-rate")


@app.command()
def simulate(
    preset: str = opts.preset_option(),
    spec_file: Path = opts.spec_option(),
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
    seed: int = typer.Option(0, parser=opts.whole_number, help="noise seed"),
    tacho_ppr: int = typer.Option(None, "--tacho-ppr", parser=opts.whole_number,
                                  help="add a tachometer channel (pulses/rev)"),
    band: tuple[float, float] = typer.Option(None, help="spectrum band LOW HIGH (Hz); default "
                                             "the mesh harmonics fm − 12 fc … 3 fm + 12 fc "
                                             "(capped at Nyquist)"),
    quiet: bool = typer.Option(False, "--quiet", help="no progress output"),
    as_json: bool = opts.json_option(),
    out: Path = opts.out_option("record.dtwin.h5, waveform.png, spectrum.png, spectrum.csv, "
                                "simulate.json, report.html"),
    force: bool = opts.force_option(),
) -> None:
    """Simulate the twin and write a record (dtwin's own format) with waveform and spectrum PNGs."""
    from ..model.faults import parse_fault
    from ..simulation.simulate import QUANTITIES
    from ..spec.build import daq_from_spec

    opts.input_speed_option("--f-sun", f_sun)
    opts.simulated_span(duration, discard)
    opts.choice("--start", start, ("steady", "rest"))
    opts.input_speed_option("--ramp-to", ramp_to)
    opts.choice("--kind", kind, ("translational", "torsional"))
    opts.positive("--sample-rate", sample_rate, unit="Hz")
    opts.choice("--quantity", quantity, QUANTITIES)
    opts.finite("--snr-db", snr_db)
    opts.count("--seed", seed, 0, opts.MAX_SEED)
    opts.at_least("--tacho-ppr", tacho_ppr, 1)
    opts.band("--band", band)
    for f in fault or []:
        parse_fault(f)
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec_file)
    spec = gb.spec
    rate = float(sample_rate) if sample_rate is not None else daq_from_spec(spec).sample_rate
    nyq = rate / 2
    if band is not None:
        opts.band("--band", band, nyquist=nyq)
    else:  # the default band starts at the mesh frequency: it must lie below Nyquist
        f_nom = f_sun or spec["operating"].get("f_sun")
        if f_nom:
            fm = float(gear_frequencies(spec, float(f_nom))["f_mesh"])
            if fm >= nyq:
                raise opts.OptionError("--sample-rate", f"the mesh frequency {fm:.4g} Hz lies "
                                       f"above Nyquist ({nyq:g} Hz at {rate:g} Hz); raise "
                                       "--sample-rate or give --band LOW HIGH below Nyquist")
    if tacho_ppr is not None:
        _check_tacho(spec, tacho_ppr, f_sun, ramp_to, rate)
    _check_memory(spec, duration, rate)
    with opts.progress_line("simulating", enabled=not (quiet or as_json)) as shown:
        record, res, settings = run_simulation(
            spec, faults=fault, f_sun=f_sun, duration=duration, discard=discard, start=start,
            ramp_to=ramp_to, kind=kind, sample_rate=sample_rate, quantity=quantity,
            snr_db=snr_db, seed=seed, tacho_ppr=tacho_ppr, progress=shown,
        )
    freqs = gear_frequencies(spec, settings["f_sun_hz"])
    if band is None:  # the gearbox's mesh harmonics with their carrier sidebands
        from ..plotting.levels import mesh_band

        band = mesh_band(freqs["f_mesh"], freqs["f_carrier"], nyq)
    report, data = spectrum_report(record, band=band, frequencies=freqs,
                                   n_planets=spec["gears"]["n_planets"])
    summary = {"settings": settings, "spectrum": report}

    def files() -> dict:
        from ..io.export import Columns
        from ..io.readers import write_record
        from ..plotting.spectrum import plot_spectrum_peaks, plot_waveform
        from ..report.html_report import HTMLReport

        unit = record.units[0]
        return {
            "record.dtwin.h5": lambda p: write_record(record, p, force=True),
            "waveform.png": plot_waveform(data["t"], data["x"], unit=unit,
                                          title=f"Simulated waveform — {spec.name}"),
            "spectrum.png": plot_spectrum_peaks(
                data["freqs"], data["spec"], data["labelled"], band=band, unit=unit,
                floor=data["floor"], title=f"Simulated spectrum — {spec.name} "
                                           f"{', '.join(fault or []) or 'healthy'}"),
            "spectrum.csv": Columns({"frequency": data["freqs"], "amplitude": data["spec"],
                                     "noise_floor": data["floor"]},
                                    {"frequency": "Hz", "amplitude": unit, "noise_floor": unit}),
            "simulate.json": summary,
            "report.html": HTMLReport(
                title=f"dtwin simulate: {spec.name}, {', '.join(fault or []) or 'healthy'}",
                summary={k: v for k, v in settings.items()
                         if isinstance(v, (str, int, float, bool)) or v is None},
                figures={"Simulated waveform": "waveform.png",
                         "Simulated spectrum": "spectrum.png"},
                tables={f"Peaks ({unit})": [
                    {"No.": pk["number"], "f (Hz)": pk["frequency_hz"],
                     "amplitude": pk["amplitude"], "dB over floor": pk["above_floor_db"],
                     "label": " | ".join(pk["labels"]) or "?"} for pk in report["peaks"]]},
                frequencies=freqs),
        }

    def table() -> None:
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
        opts.print_table(table)

    opts.emit(summary, json_out=as_json, table=table, out=out, force=force, files=files,
              gearbox=gb, seed=seed, parameters=settings)
