"""``dtwin spectrum``: amplitude spectrum of a record with numbered, labelled peaks.

    dtwin spectrum RECORD [--channel C] [--band 450 550] [--window hann]
                   [--preset paper-sim|paper-bench | --spec FILE] [--f-sun HZ]
                   [--planet-fault paper|both_flanks] [--threshold-db 10] [--min-spacing HZ]
                   [--max-peaks 15] [--floor-width 31] [--sample-rate HZ]
                   [--json] [--out DIR] [--force]

The record is read with :func:`dtwin.io.readers.read_record` (any supported format; dtwin's own
``*.dtwin.h5``). Peaks in the band standing ``--threshold-db`` above the running-median noise
floor are numbered 1, 2, … by frequency and, with a gearbox (``--preset``/``--spec``), labelled
as ``m fm + a fc + b fs/N + c fp`` within one frequency bin (:mod:`dtwin.spectrum`). The input
speed is ``--f-sun``, else the record's tachometer (mean speed), else the record's
``metadata["f_sun"]``, else the spec's ``operating.f_sun``; the report names the source.

Terminal: a table of the peaks and their labels. ``--json``: the report on stdout. ``--out DIR``:
``spectrum.png`` (zoomed spectrum with numbered peaks and the label table), ``waveform.png``,
``spectrum.json`` and ``manifest.json``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import typer

from ..errors import RecordError, SpecError
from .app import app

# --- helpers shared with cmd_view ---------------------------------------------------------------


def load_gearbox(preset: str | None, spec_file: Path | None):
    """The :class:`dtwin.spec.Spec` of ``--preset`` or ``--spec`` (None if neither)."""
    if preset is not None and spec_file is not None:
        raise SpecError([("--preset/--spec", "give at most one of --preset NAME or --spec FILE")])
    if preset is None and spec_file is None:
        return None
    from .. import spec as spec_mod

    return spec_mod.preset(preset) if preset is not None else spec_mod.load_spec(spec_file)


def read_input(path: Path, sample_rate: float | None):
    """Read a record file (read-only) with :func:`dtwin.io.readers.read_record`."""
    from ..io.readers import read_record

    return read_record(path, sample_rate=sample_rate)


def _tacho_speed(record) -> tuple[float, str] | None:
    if record.tacho is None or not record.tacho_ppr:
        return None
    from ..order import tacho_angle

    ang = tacho_angle(record.tacho, record.sample_rate, int(record.tacho_ppr))
    return (ang[-1] - ang[0]) / (2 * np.pi * record.duration), record.tacho_shaft or "sun"


def input_speed(record, spec, f_sun: float | None) -> tuple[float | None, str | None]:
    """Input (sun) speed in Hz and where it came from (module docstring); (None, None) if none."""
    if f_sun is not None:
        if not 0 < f_sun <= 500:
            hint = f" (did you mean {f_sun / 60:g} Hz = {f_sun:g} rpm?)" if f_sun > 500 else ""
            raise SpecError([("--f-sun", f"must be the input speed in Hz in (0, 500]{hint}")])
        return float(f_sun), "--f-sun"
    tacho = _tacho_speed(record)
    if tacho is not None:
        speed, shaft = tacho
        if shaft == "sun":
            return float(speed), "tachometer (sun)"
        if spec is not None:
            gs = spec.gear_set()
            return float(speed * (gs.z_sun + gs.z_ring) / gs.z_sun), "tachometer (carrier)"
    meta = record.metadata.get("f_sun") if isinstance(record.metadata, dict) else None
    if isinstance(meta, (int, float)) and meta > 0:
        return float(meta), "record metadata f_sun"
    if spec is not None and spec["operating"].get("f_sun"):
        return float(spec["operating"]["f_sun"]), "spec operating.f_sun"
    return None, None


def gear_frequencies(spec, f_sun: float | None, planet_fault: str = "paper") -> dict | None:
    """Characteristic frequencies (Hz) from :func:`dtwin.gears.characteristic_frequencies`."""
    if spec is None:
        return None
    if f_sun is None:
        raise SpecError([("--f-sun", "the input speed is unknown: pass --f-sun HZ, give the "
                          "record a tachometer, or use a spec with operating.f_sun")])
    from ..gears import characteristic_frequencies

    return characteristic_frequencies(spec.gear_set(), f_sun, planet_fault=planet_fault)


def channel_unit(record, channel: str | int) -> tuple[str, str]:
    i = record.index(channel)
    return record.channels[i], record.units[i] or "-"


def open_output(out: Path, force: bool, inputs: list, spec, parameters: dict):
    from ..io.output import OutputFolder

    spec_dict = None
    if spec is not None:
        from ..spec import spec_to_dict

        spec_dict = spec_to_dict(spec)
    return OutputFolder(out, force=force, inputs=[p for p in inputs if p is not None],
                        spec=spec_dict, parameters=parameters)


def channel_token(channel: str) -> str | int:
    return int(channel) if channel.lstrip("-").isdigit() else channel


# --- the report ---------------------------------------------------------------------------------


def spectrum_report(
    record,
    *,
    channel: str | int = 0,
    band: tuple[float, float] = (450.0, 550.0),
    window: str = "hann",
    frequencies: dict | None = None,
    n_planets: int = 3,
    threshold_db: float = 10.0,
    min_spacing_hz: float | None = None,
    max_peaks: int | None = 15,
    floor_width: int = 31,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Spectrum, peaks and labels of one channel of a :class:`dtwin.io.Record`.

    **Arguments:** `frequencies`: characteristic frequencies (Hz, registry names) to label with,
    or None (peaks unlabelled); `n_planets` for the "fs/N" labels; the rest as
    :func:`dtwin.spectrum.find_peaks`.

    **Returns:** ``(report, data)``: the JSON-ready report and the arrays for the figures
    (``freqs``, ``spec``, ``floor``, ``labelled``, ``t``, ``x``, ``unit``).
    """
    from ..spectrum import (
        FrequencyBasis,
        amplitude_spectrum,
        find_peaks,
        label_peaks,
        noise_floor,
        time_stats,
    )

    name, unit = channel_unit(record, channel)
    nyq = record.sample_rate / 2
    if not 0 <= band[0] < band[1] <= nyq:
        raise RecordError(f"--band {band[0]:g} {band[1]:g} must satisfy 0 <= low < high <= "
                          f"{nyq:g} Hz (half the record's sampling rate)")
    x = record.channel(channel)
    if not np.all(np.isfinite(x)):
        raise RecordError(f"channel {name!r} holds NaN or inf samples; clean the record first")
    freqs, spec = amplitude_spectrum(x, record.sample_rate, window)
    floor = noise_floor(spec, floor_width)
    peaks = find_peaks(freqs, spec, threshold_db=threshold_db, min_spacing_hz=min_spacing_hz,
                       band=band, floor=floor, max_peaks=max_peaks)
    df = float(freqs[1] - freqs[0])
    if frequencies is not None:
        basis = FrequencyBasis(frequencies["f_mesh"], frequencies["f_carrier"],
                               frequencies.get("f_sun_fault"), frequencies.get("f_planet_fault"),
                               n_planets)
        labelled = label_peaks(peaks, basis, df)
    else:
        from ..spectrum import LabelledPeak

        labelled = [LabelledPeak(k, p, ()) for k, p in enumerate(peaks, start=1)]
    stats = time_stats(x)
    sel = (freqs >= band[0]) & (freqs <= band[1])
    report = {
        "channel": name,
        "unit": unit,
        "sample_rate_hz": float(record.sample_rate),
        "duration_s": float(record.duration),
        "window": window,
        "band_hz": [float(band[0]), float(band[1])],
        "resolution_hz": df,
        "noise_floor_median": float(np.median(floor[sel])) if sel.any() else None,
        "threshold_db": threshold_db,
        "time_stats": {"rms": float(stats.rms), "kurtosis": float(stats.kurtosis),
                       "crest_factor": float(stats.crest_factor)},
        "frequencies_hz": frequencies,
        "peaks": [
            {"number": lp.number, "frequency_hz": lp.peak.frequency,
             "amplitude": lp.peak.amplitude, "above_floor_db": lp.peak.above_floor_db,
             "labels": [lab.text for lab in lp.labels],
             "label_coefficients": [[lab.m, lab.a, lab.b, lab.c] for lab in lp.labels],
             "label_error_hz": [lab.error for lab in lp.labels],
             "alternatives": [lab.text for lab in lp.alternatives[:5]],
             "n_alternatives": lp.n_alternatives}
            for lp in labelled
        ],
    }
    data = {"freqs": freqs, "spec": spec, "floor": floor, "labelled": labelled,
            "t": record.time, "x": x, "unit": unit}
    return report, data


def _print_table(report: dict, title: str) -> None:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    table = Table(title=escape(title))
    for col, just in (("No.", "right"), ("f (Hz)", "right"), (f"amplitude ({report['unit']})",
                      "right"), ("dB over floor", "right"), ("label", "left"),
                      ("next alternative", "left")):
        table.add_column(col, justify=just)
    for p in report["peaks"]:
        table.add_row(str(p["number"]), f"{p['frequency_hz']:.2f}", f"{p['amplitude']:.4g}",
                      f"{p['above_floor_db']:.1f}", " | ".join(p["labels"]) or "?",
                      (p["alternatives"][0] + (f" (+{p['n_alternatives'] - 1})"
                                               if p["n_alternatives"] > 1 else ""))
                      if p["alternatives"] else "")
    console = Console()
    console.print(table)
    s = report["time_stats"]
    console.print(f"RMS {s['rms']:.4g} {report['unit']}, kurtosis {s['kurtosis']:.3f}, crest "
                  f"factor {s['crest_factor']:.3f}; resolution {report['resolution_hz']:.4g} Hz")


@app.command()
def spectrum(
    record_file: Path = typer.Argument(..., help="Record file (any supported format)."),
    channel: str = typer.Option("0", "--channel", help="Channel name or index."),
    band: tuple[float, float] = typer.Option((450.0, 550.0), "--band",
                                             help="Frequency band LOW HIGH (Hz)."),
    window: str = typer.Option("hann", "--window",
                               help="rect, hann, hamming, blackman, blackmanharris, flattop."),
    preset: str | None = typer.Option(None, "--preset", help="Gearbox preset (paper-sim, "
                                      "paper-bench, lin-parker) for the peak labels."),
    spec: Path | None = typer.Option(None, "--spec", help="Gearbox spec file (TOML)."),
    f_sun: float | None = typer.Option(None, "--f-sun", help="Input (sun) speed in Hz."),
    planet_fault: str = typer.Option("paper", "--planet-fault",
                                     help="paper (f_mesh/Zp) or both_flanks (2 f_mesh/Zp)."),
    threshold_db: float = typer.Option(10.0, "--threshold-db",
                                       help="Peak height above the noise floor (dB)."),
    min_spacing: float | None = typer.Option(None, "--min-spacing",
                                             help="Minimum distance between peaks (Hz)."),
    max_peaks: int = typer.Option(15, "--max-peaks", help="Keep the highest N peaks."),
    floor_width: int = typer.Option(31, "--floor-width",
                                    help="Running-median window of the noise floor (bins)."),
    sample_rate: float | None = typer.Option(None, "--sample-rate",
                                             help="Sampling rate (Hz) if the file states none."),
    json_out: bool = typer.Option(False, "--json", help="Print the report as JSON on stdout."),
    out: Path | None = typer.Option(None, "--out", help="Write PNGs, spectrum.json, manifest."),
    force: bool = typer.Option(False, "--force", help="Overwrite results in --out."),
) -> None:
    """Amplitude spectrum of a record with numbered peaks labelled by gear frequencies."""
    gearbox = load_gearbox(preset, spec)
    record = read_input(record_file, sample_rate)
    ch = channel_token(channel)
    fsun, fsun_source = input_speed(record, gearbox, f_sun)
    freqs = gear_frequencies(gearbox, fsun, planet_fault)
    n_planets = gearbox.gear_set().n_planets if gearbox is not None else 3
    report, data = spectrum_report(
        record, channel=ch, band=band, window=window, frequencies=freqs, n_planets=n_planets,
        threshold_db=threshold_db, min_spacing_hz=min_spacing, max_peaks=max_peaks,
        floor_width=floor_width)
    report = {"record": str(record_file), "f_sun_hz": fsun, "f_sun_source": fsun_source,
              "gearbox": preset or (str(spec) if spec else None), **report}
    if json_out:
        typer.echo(json.dumps(_jsonable(report), indent=2))
    else:
        _print_table(report, f"{record_file.name}, channel {report['channel']}, "
                     f"{band[0]:g}–{band[1]:g} Hz" + ("" if freqs else " (no gearbox: unlabelled)"))
    if out is not None:
        from ..plotting.spectrum import plot_spectrum_peaks, plot_waveform

        folder = open_output(out, force, [record_file, spec], gearbox,
                             {"channel": report["channel"], "band": list(band), "window": window,
                              "f_sun": fsun, "threshold_db": threshold_db})
        title = f"{record_file.name} [{report['channel']}]"
        fig = plot_spectrum_peaks(data["freqs"], data["spec"], data["labelled"], band=band,
                                  unit=data["unit"], floor=data["floor"],
                                  title=f"Amplitude spectrum ({window} window), {title}")
        folder.savefig("spectrum.png", fig)
        folder.savefig("waveform.png", plot_waveform(data["t"], data["x"], unit=data["unit"],
                                                     title=f"Time waveform, {title}"))
        folder.write_json("spectrum.json", report)
        if not json_out:
            typer.echo(f"wrote {folder.path}/spectrum.png, waveform.png, spectrum.json, "
                       "manifest.json", err=True)


def _jsonable(obj):
    from ..io.output import to_jsonable

    return to_jsonable(obj)
