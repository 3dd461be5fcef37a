"""``dtwin spectrum``: amplitude spectrum of a record with numbered, labelled peaks.

    dtwin spectrum RECORD [--channel C|all|GROUP|C1,C2] [--band LOW HIGH] [--window hann]
                   [--scale db|linear] [--units m/s^2|g|mm/s|um] [--highpass 10]
                   [--welch --segment 4096 --overlap 0.5] [--iso-group 2 --iso-support rigid]
                   [--preset paper-sim|paper-bench | --spec FILE] [--f-sun HZ]
                   [--tacho CHANNEL[:PPR[:SHAFT]]]
                   [--planet-fault paper|both_flanks] [--threshold-db 10] [--min-spacing HZ]
                   [--max-peaks 15] [--floor-width 31] [--sample-rate HZ]
                   [--json] [--out DIR] [--force]

The record is read with :func:`dtwin.io.readers.read_record` (any supported format; dtwin's own
``*.dtwin.h5``). Peaks in the band standing ``--threshold-db`` above the running-median noise
floor are numbered 1, 2, … by frequency and, with a gearbox (``--preset``/``--spec``), labelled
as ``m fm + a fc + b fs/N + c fp`` within one frequency bin (:mod:`dtwin.signal.spectrum`). The input
speed follows :func:`dtwin.identify.operating_point.resolve_speed`: ``--f-sun``, else the
tachometer (``--tacho`` or the record's own; mean speed), else the record's
``metadata["f_sun"]``, else (with a gearbox) the speed the record's mesh lines give, else the
spec's ``operating.f_sun``; the report names the source, and a speed the record's lines
contradict is warned about, naming the lines (expected and seen frequencies).

The band defaults to the gearbox's mesh harmonics (``fm − 12 fc … 3 fm + 12 fc``, capped at
Nyquist), or the whole spectrum without a gearbox. ``--units`` converts (g: 9.80665 m/s²;
velocity and displacement by integration behind the ``--highpass``, :mod:`dtwin.signal.units`); every
vibration channel also gets its broadband velocity RMS (``--highpass`` … 1000 Hz) and its ISO
20816-3 zone (``--iso-group``, ``--iso-support``). Several channels (``all``, a group such as a
triaxial sensor, or a comma list) give one figure and one table each.

Terminal: a table of the peaks and their labels. ``--json``: the report on stdout (one channel:
as before; several: ``channels``, one report each). ``--out DIR``: ``spectrum.png`` (spectrum
over the band in dB re 1 µm/s² or linear, ``--scale``, numbered peaks and the label table),
``waveform.png``, ``iso20816.png``, the arrays ``spectrum.csv``/``.npz`` (frequency, amplitude,
noise floor with units) and ``waveform.csv``/``.npz``, ``spectrum.json``, ``report.html`` and
``manifest.json`` (with several channels the per-channel files end in ``_<channel>``).
"""

from __future__ import annotations

from pathlib import Path

import typer

from ..report.analyses import gear_frequencies, operating_point, spectrum_report
from . import options as opts
from .app import app

_PRESET_HELP = ("Gearbox for the peak labels: " + ", ".join(opts.PRESETS) + ".")

def _print_table(report: dict, title: str) -> None:
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
    console = opts.console()
    opts.print_table(table)
    s = report["time_stats"]
    console.print(f"RMS {s['rms']:.4g} {report['unit']}, kurtosis {s['kurtosis']:.3f}, crest "
                  f"factor {s['crest_factor']:.3f}; resolution {report['resolution_hz']:.4g} Hz")


#: Widest running-median window of the noise floor `--floor-width` accepts (bins).
MAX_FLOOR_WIDTH = 10_001


@app.command()
def spectrum(
    record_file: Path = typer.Argument(..., help="Record file (any supported format)."),
    channel: str = typer.Option("0", "--channel", help="Channel name or index, a comma list, a "
                                "group (a triaxial sensor's name) or 'all': one figure each."),
    band: tuple[float, float] | None = typer.Option(
        None, "--band", help="Frequency band LOW HIGH (Hz) of the peaks and the figure; default "
        "the gearbox's mesh harmonics (fm − 12 fc … 3 fm + 12 fc, capped at Nyquist), or the "
        "whole spectrum without a gearbox."),
    scale: str = typer.Option("db", "--scale", help="Figure levels: db (dB re the unit's ISO "
                              "1683 reference: 1 µm/s², 1 nm/s, 1 pm; 1 g) or linear."),
    units: str | None = typer.Option(None, "--units", help="Output unit: m/s^2, g, mm/s, um "
                                     "(acceleration integrated behind --highpass); default as "
                                     "recorded."),
    highpass: float = typer.Option(10.0, "--highpass", help="High-pass (Hz, 4th-order "
                                   "Butterworth, zero phase) of the integration to mm/s or um "
                                   "and the lower edge of the ISO 20816 band."),
    welch: bool = typer.Option(False, "--welch", help="Welch-averaged amplitude spectrum "
                               "(segments of --segment samples overlapping by --overlap)."),
    segment: int = typer.Option(4096, "--segment", parser=opts.whole_number,
                                help="Welch segment (samples; resolution sample rate / "
                                     "segment)."),
    overlap: float = typer.Option(0.5, "--overlap", help="Welch overlap (fraction in [0, 1))."),
    iso_group: int = typer.Option(2, "--iso-group", help="ISO 20816-3 machine group of the "
                                  "zone lines: 1 (300 kW–50 MW) or 2 (15–300 kW)."),
    iso_support: str = typer.Option("rigid", "--iso-support", help="ISO 20816-3 support: rigid "
                                    "or flexible."),
    window: str = typer.Option("hann", "--window",
                               help="rect, hann, hamming, blackman, blackmanharris, flattop."),
    preset: str | None = opts.preset_option(_PRESET_HELP),
    spec: Path | None = opts.spec_option(),
    f_sun: float | None = opts.f_sun_option(),
    tacho: str | None = opts.tacho_option(),
    planet_fault: str = typer.Option("paper", "--planet-fault",
                                     help="paper (f_mesh/Zp) or both_flanks (2 f_mesh/Zp)."),
    threshold_db: float = typer.Option(10.0, "--threshold-db",
                                       help="Peak height above the noise floor (dB)."),
    min_spacing: float | None = typer.Option(None, "--min-spacing",
                                             help="Minimum distance between peaks (Hz)."),
    max_peaks: int = typer.Option(15, "--max-peaks", parser=opts.whole_number,
                                  help="Keep the highest N peaks."),
    floor_width: int = typer.Option(31, "--floor-width", parser=opts.whole_number,
                                    help="Running-median window of the noise floor (bins, at "
                                         f"most {MAX_FLOOR_WIDTH})."),
    sample_rate: float | None = opts.sample_rate_option(),
    json_out: bool = opts.json_option(),
    out: Path | None = opts.out_option("spectrum.png, waveform.png, iso20816.png, spectrum.json, "
                                       "spectrum.csv/.npz, waveform.csv/.npz, report.html"),
    force: bool = opts.export_force_option(),
    export: Path | None = opts.export_option(
        "the spectrum (frequency, amplitude, noise floor, with units) to this file: .csv, .npz "
        "or .h5/.hdf5 (HDF5: one group per channel)."),
) -> None:
    """Amplitude spectrum of a record with numbered peaks labelled by gear frequencies."""
    from ..io.export import check_export_path
    from ..signal import units as units_mod
    from ..signal.spectrum import WINDOWS

    if export is not None:
        check_export_path(export, force=force, inputs=[record_file])

    opts.band("--band", band)
    opts.choice("--window", window, tuple(WINDOWS))
    opts.choice("--scale", scale, ("db", "linear"))
    if units is not None and units_mod.normalise_unit(units) is None:
        raise opts.OptionError("--units", f"unknown unit {units!r}; use one of "
                               f"{', '.join(units_mod.UNITS)}")
    opts.positive("--highpass", highpass, unit="Hz")
    opts.at_least("--segment", segment, 16)
    opts.in_range("--overlap", overlap, 0.0, 0.95)
    opts.choice("--iso-support", iso_support, ("rigid", "flexible"))
    opts.choice("--iso-group", str(iso_group), ("1", "2"))
    opts.input_speed_option("--f-sun", f_sun)
    opts.choice("--planet-fault", planet_fault, ("paper", "both_flanks"))
    opts.in_range("--threshold-db", threshold_db, 0.0, 200.0, "dB")
    opts.positive("--min-spacing", min_spacing, unit="Hz")
    opts.at_least("--max-peaks", max_peaks, 1)
    opts.count("--floor-width", floor_width, 3, MAX_FLOOR_WIDTH, "a running median wider "
               "than that is no longer the floor around a peak, and its window is held in "
               "memory")
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec, required=False)
    gearbox = gb.spec if gb is not None else None
    record = opts.read_record(record_file, sample_rate, tacho)
    try:
        rows = record.channel_list(opts.channel_token(channel))
    except Exception:  # noqa: BLE001 - one message listing the channels
        opts.check_channel(record, opts.channel_token(channel))
        raise
    op = operating_point(record, gearbox, f_sun, channel=rows[0])
    fsun, fsun_source = (None, None) if op is None else (op.f_sun, op.source)
    opts.checked_record(record, rows, gearbox, fsun)
    nyq = record.sample_rate / 2
    opts.band("--band", band, nyquist=nyq)
    freqs = gear_frequencies(gearbox, fsun, planet_fault)
    n_planets = gearbox.gear_set().n_planets if gearbox is not None else 3
    if band is None:
        from ..plotting.levels import mesh_band

        band = (mesh_band(freqs["f_mesh"], freqs["f_carrier"], nyq) if freqs
                else (0.0, nyq))
    if welch and segment > record.n_samples:
        raise opts.OptionError("--segment", f"{segment} samples exceed the record "
                               f"({record.n_samples}); lower it")
    zones = units_mod.iso20816_zones(iso_group, iso_support)
    iso_band = (highpass, min(1000.0, nyq))
    reports, datas = [], []
    for i in rows:
        one = _channel_record(record, i, units, highpass, units_mod)
        with opts.working(f"spectrum of {record.channels[i]}"):
            rep, data = spectrum_report(
                one, channel=0, band=band, window=window, frequencies=freqs,
                n_planets=n_planets, threshold_db=threshold_db, min_spacing_hz=min_spacing,
                max_peaks=max_peaks, floor_width=floor_width,
                welch=(segment, overlap) if welch else None)
        if units is not None and units_mod.quantity(units) != units_mod.quantity(record.units[i]):
            rep["integration"] = {"highpass_hz": highpass, "highpass_order": 4,
                                  "method": "frequency domain, zero phase (dtwin.signal.units)"}
        if units_mod.quantity(one.units[0]) is not None:
            v = units_mod.broadband_velocity_rms(one.channel(0), one.sample_rate, one.units[0],
                                                 band=iso_band)
            rep["iso20816"] = {"velocity_rms_mm_s": v, "band_hz": list(iso_band),
                               "zone": units_mod.iso20816_zone(v, zones),
                               "zones_mm_s": zones.boundaries, "classification": zones.description}
        if rep.get("labels_withheld"):
            from .logs import warn

            warn(rep["labels_withheld"])
        reports.append(rep)

        datas.append(data)
    head = {"record": str(record_file), "f_sun_hz": fsun, "f_sun_source": fsun_source,
            **({"operating_point": op.to_dict()} if op is not None else {}),
            "gearbox": gb.source if gb is not None else None}
    report = ({**head, **reports[0]} if len(reports) == 1
              else {**head, "channels": reports})

    def files() -> dict:
        from ..io.export import Columns
        from ..plotting.spectrum import plot_spectrum_peaks, plot_waveform
        from ..plotting.views import plot_iso20816
        from ..report.html_report import HTMLReport

        out_files: dict = {"spectrum.json": report}
        figures: dict = {}
        for rep, data in zip(reports, datas, strict=True):
            sfx = "" if len(reports) == 1 else f"_{_safe(rep['channel'])}"
            title = f"{record_file.name} [{rep['channel']}]"
            how = f"Welch, {segment}-sample segments" if welch else f"{window} window"
            out_files[f"spectrum{sfx}.png"] = plot_spectrum_peaks(
                data["freqs"], data["spec"], data["labelled"], band=band, unit=data["unit"],
                floor=data["floor"], scale=scale, title=f"Amplitude spectrum ({how}), {title}")
            out_files[f"waveform{sfx}.png"] = plot_waveform(
                data["t"], data["x"], unit=data["unit"], title=f"Time waveform, {title}")
            out_files[f"spectrum{sfx}.csv"] = Columns(
                {"frequency": data["freqs"], "amplitude": data["spec"],
                 "noise_floor": data["floor"]},
                {"frequency": "Hz", "amplitude": data["unit"], "noise_floor": data["unit"]})
            out_files[f"waveform{sfx}.csv"] = Columns(
                {"time": data["t"], rep["channel"]: data["x"]},
                {"time": "s", rep["channel"]: data["unit"]})
            figures[f"Amplitude spectrum, {title}"] = f"spectrum{sfx}.png"
            figures[f"Time waveform, {title}"] = f"waveform{sfx}.png"
        iso = {r["channel"]: r["iso20816"]["velocity_rms_mm_s"] for r in reports
               if "iso20816" in r}
        if iso:
            out_files["iso20816.png"] = plot_iso20816(iso, zones, band=iso_band)
            figures["Broadband velocity RMS against ISO 20816 zones"] = "iso20816.png"
        out_files["report.html"] = HTMLReport(
            title=f"dtwin spectrum: {record_file.name}",
            summary={k: v for k, v in head.items()} | {"band (Hz)": list(band)},
            figures=figures,
            tables={f"Peaks, {r['channel']} ({r['unit']})": [
                {"No.": p["number"], "f (Hz)": p["frequency_hz"], "amplitude": p["amplitude"],
                 "dB over floor": p["above_floor_db"], "label": " | ".join(p["labels"]) or "?"}
                for p in r["peaks"]] for r in reports}
            | ({"ISO 20816 evaluation": [{"channel": c, "velocity RMS (mm/s)": v,
                                          "zone": next(r["iso20816"]["zone"] for r in reports
                                                       if r["channel"] == c)}
                                         for c, v in iso.items()]} if iso else {}),
            notes=[zones.description] if iso else [], frequencies=freqs)
        return out_files

    if export is not None:
        _export(export, reports, datas, head)

    def table() -> None:
        for rep in reports:
            _print_table({**head, **rep}, f"{record_file.name}, channel {rep['channel']}, "
                         f"{band[0]:g}–{band[1]:g} Hz"
                         + ("" if freqs else " (no gearbox: unlabelled)"))
            if "iso20816" in rep:
                z = rep["iso20816"]
                opts.console().print(f"velocity RMS {z['velocity_rms_mm_s']:.3g} mm/s "
                                     f"({z['band_hz'][0]:g}–{z['band_hz'][1]:g} Hz): ISO 20816 "
                                     f"zone {z['zone']} ({zones.description})")

    opts.emit(report, json_out=json_out, out=out, force=force, files=files, table=table,
              inputs=[record_file], gearbox=gb,
              parameters={"channels": [r["channel"] for r in reports], "band": list(band),
                          "window": window, "f_sun": fsun, "threshold_db": threshold_db,
                          "scale": scale, "units": units, "highpass_hz": highpass,
                          "welch": {"segment": segment, "overlap": overlap} if welch else None})


def _export(path: Path, reports: list, datas: list, head: dict) -> None:
    """``--export``: the spectra of every channel to one file (CSV/NPZ: one table, the
    channels' columns side by side on their shared frequency axis; HDF5: a group each)."""
    from ..io.export import Columns, export_arrays
    from .logs import note

    sets = {}
    for rep, data in zip(reports, datas, strict=True):
        name = "spectrum" if len(reports) == 1 else f"spectrum_{_safe(rep['channel'])}"
        sets[name] = Columns({"frequency": data["freqs"], "amplitude": data["spec"],
                              "noise_floor": data["floor"]},
                             {"frequency": "Hz", "amplitude": data["unit"],
                              "noise_floor": data["unit"]})
    if len(reports) > 1 and path.suffix.lower() in (".csv", ".npz"):
        cols, units = {"frequency": datas[0]["freqs"]}, {"frequency": "Hz"}
        for rep, data in zip(reports, datas, strict=True):
            ch = _safe(rep["channel"])
            cols |= {f"amplitude_{ch}": data["spec"], f"noise_floor_{ch}": data["floor"]}
            units |= {f"amplitude_{ch}": data["unit"], f"noise_floor_{ch}": data["unit"]}
        sets = {"spectrum": Columns(cols, units)}
    export_arrays(path, sets, attrs={"record": head["record"], "command": "dtwin spectrum",
                                     "f_sun_hz": head["f_sun_hz"] or float("nan")})
    note(f"wrote {path}")


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in str(name))


def _channel_record(record, i: int, units: str | None, highpass: float, units_mod):
    """Channel `i` of `record` as a one-channel record, converted to `units` (if given)."""
    import dataclasses

    sub = record.select([i])
    if units is None:
        return sub
    unit = sub.units[0]
    if units_mod.quantity(unit) is None:
        raise opts.OptionError("--units", f"channel {sub.channels[0]!r} is in {unit or 'no unit'}"
                               ", not a vibration unit; give the sensitivity when reading it "
                               "(dtwin record convert) or drop --units")
    x = units_mod.convert_signal(sub.channel(0), sub.sample_rate, unit, units,
                                 highpass_hz=highpass)
    return dataclasses.replace(sub, data=x[None, :], units=(units_mod.normalise_unit(units),))
