"""``dtwin view``: the classic signal-processing views of a record.

    dtwin view RECORD --kind order|ordermap|tsa|envelope|kurtogram|cepstrum|waterfall|psd
               [--channel C] [--preset P | --spec FILE] [--f-sun HZ] [--band LOW HIGH]
               [--speed-range LOW HIGH] [--segment N] [--nat HZ ...] [--revs 4]
               [--scale db|linear] [--units m/s^2|g|mm/s|um] [--highpass 10] [--sample-rate HZ]
               [--json] [--out DIR] [--force]

- ``order``: order spectrum of the input (sun) shaft after angular resampling; the angle comes
  from the record's tachometer, else (with a gearbox) from the mesh phase
  (:func:`dtwin.signal.order.mesh_angle`, speed searched in ``--speed-range``, default ±20 % of the
  input speed). Peaks are labelled in orders like ``dtwin spectrum`` labels frequencies.
- ``ordermap`` (run-ups): order spectra of successive stretches of ``--revs`` revolutions
  against the input speed (rpm), as a colour map (order vs rpm, ``ordermap.png``), and the
  order cuts (``ordercuts.png``: fm, fm ± N fc, 2 fm against rpm, read by Parseval over each
  order's main lobe, :func:`dtwin.signal.order.order_cuts`); the angle from the tachometer or, without
  one, from the mesh phase (the estimated speed).
- ``tsa`` (gearbox needed): TSA on the carrier (indicators RMS, kurtosis, crest factor, FM0, FM4
  with mesh order Zr), TSA of the sun relative to the carrier (mesh order Zs) and McFadden's
  planet separation (FM4 per planet). Planet numbers are absolute only with a carrier tacho
  whose first pulse marks carrier angle 0; otherwise the angle origin is unknown and the planet
  numbering is relative (the report says which).
- ``envelope``: envelope spectrum of ``--band`` or, without it, of the kurtogram's band, with
  the fault frequencies marked.
- ``kurtogram``: fast kurtogram and the band it picks.
- ``cepstrum``: real cepstrum with the rahmonics of fc, N·fc and fs/N marked.
- ``waterfall``: STFT waterfall (``--segment`` samples) and, with a shaft angle, a Campbell
  diagram with the mesh orders and the natural frequencies given by ``--nat``.
- ``psd``: Welch PSD (``--segment`` samples per segment), total RMS and the RMS of ``--band``.

Spectrum-like views are in dB re the unit's ISO 1683 reference (1 µm/s² for acceleration) or
linear (``--scale``).

Terminal: a short summary table; ``--json``: the report on stdout; ``--out DIR``: ``KIND.png``
(and further PNGs), the arrays behind them as ``KIND.csv``/``.npz`` (named columns with units;
maps in long form in the CSV, as a grid in the NPZ; ``tsa.csv``, ``tsa_sun.csv`` and
``planets.csv`` for the TSA, ``kurtogram.csv`` one row per band), ``view_KIND.json``,
``report.html`` and ``manifest.json``. ``--export FILE`` writes the arrays to one file (.csv,
.npz, .h5; :func:`dtwin.io.export.export_arrays`), with or without ``--out``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import typer

from ..errors import RecordError
from ..io.export import Columns, Grid
from ..report.analyses import channel_unit, gear_frequencies, input_speed
from . import options as opts
from .app import app
from .options import channel_token

KINDS = ("order", "ordermap", "tsa", "envelope", "kurtogram", "cepstrum", "waterfall", "psd")


def _pow2(v: float) -> int:
    return int(2 ** np.ceil(np.log2(max(v, 4.0))))


def shaft_angles(record, x: np.ndarray, gearbox, f_sun: float | None,
                 speed_range: tuple[float, float] | None) -> dict[str, Any]:
    """Sun and carrier angles (rad) at every sample, and how they were obtained.

    Returns a dict with ``sun`` and ``carrier`` (arrays or None), ``source`` and
    ``absolute_carrier`` (True when a carrier tachometer fixes the carrier's angle origin).
    """
    from ..signal.order import mesh_angle, tacho_angle

    gs = gearbox.gear_set() if gearbox is not None else None
    ratio = (gs.z_sun + gs.z_ring) / gs.z_sun if gs is not None else None  # sun / carrier
    if record.tacho is not None and record.tacho_ppr:
        ang = tacho_angle(record.tacho, record.sample_rate, int(record.tacho_ppr))
        shaft = record.tacho_shaft or "sun"
        if shaft == "carrier":
            return {"sun": ang * ratio if ratio else None, "carrier": ang,
                    "source": "tachometer on the carrier", "absolute_carrier": True}
        return {"sun": ang, "carrier": ang / ratio if ratio else None,
                "source": "tachometer on the sun", "absolute_carrier": False}
    if gs is None or f_sun is None:
        raise opts.OptionError("--preset/--spec", "this view needs the shaft angle: the record "
                               "has no tachometer, so give the gearbox (--preset or --spec) and "
                               "its input speed (--f-sun) to track the mesh phase")
    mo = gs.z_sun * gs.z_ring / (gs.z_sun + gs.z_ring)
    co = gs.z_sun / (gs.z_sun + gs.z_ring)
    rng = speed_range or (0.8 * f_sun, 1.2 * f_sun)
    sun = mesh_angle(x, record.sample_rate, mo, rng, bandwidth=0.45 * co)
    return {"sun": sun, "carrier": sun / ratio, "source": "mesh phase (no tachometer)",
            "absolute_carrier": False}


def _order_view(record, x, unit, gearbox, freqs, f_sun, speed_range, scale="db"):
    from ..plotting.views import plot_order_spectrum
    from ..signal.order import order_spectrum, resample_to_angle, shaft_speed
    from ..signal.spectrum import FrequencyBasis, find_peaks, label_peaks

    ang = shaft_angles(record, x, gearbox, f_sun, speed_range)
    if ang["sun"] is None:
        raise opts.OptionError("--preset/--spec", "the tachometer is on the carrier: give the "
                               "gearbox to convert its angle to the input shaft")
    speed = shaft_speed(ang["sun"], record.sample_rate)
    f_lo, f_hi = float(np.percentile(speed, 1)), float(np.percentile(speed, 99))
    if f_lo <= 0:
        raise RecordError("the input shaft stands still in part of the record; cut it to the "
                          "part where it turns")
    if freqs is not None:
        mo = freqs["f_mesh"] / freqs["f_sun"]
        spr = _pow2(2.5 * 2.5 * mo * f_hi / f_lo)
    else:
        spr = _pow2(record.sample_rate / f_hi)
    _, xa = resample_to_angle(x, record.sample_rate, ang["sun"], spr)
    orders, amp = order_spectrum(xa, spr, "hann")
    max_order = float(orders[-1])
    marks, labelled = None, []
    peaks = find_peaks(orders, amp, threshold_db=10.0, max_peaks=15)
    if freqs is not None:
        o = {k: v / freqs["f_sun"] for k, v in freqs.items()}
        gs = gearbox.gear_set()
        basis = FrequencyBasis(o["f_mesh"], o["f_carrier"], o["f_sun_fault"], o["f_planet_fault"],
                               gs.n_planets)
        labelled = label_peaks(peaks, basis, float(orders[1] - orders[0]))
        marks = {"fm": o["f_mesh"], "fm − N fc": o["f_mesh"] - o["f_planet_pass"],
                 "fm + N fc": o["f_mesh"] + o["f_planet_pass"]}
        max_order = min(max_order, 2.5 * o["f_mesh"])
    report = {
        "angle_source": ang["source"], "samples_per_rev": spr,
        "speed_hz": {"min": f_lo, "max": f_hi, "mean": float(np.mean(speed))},
        "order_resolution": float(orders[1] - orders[0]),
        "peaks": [{"order": p.frequency, "amplitude": p.amplitude,
                   "above_floor_db": p.above_floor_db,
                   "labels": [lab.text for lab in labelled[i].labels] if labelled else []}
                  for i, p in enumerate(peaks)],
    }
    fig = plot_order_spectrum(orders, amp, marks=marks, unit=unit, max_order=max_order,
                              shaft="input (sun) shaft", scale=scale,
                              title=f"Order spectrum ({ang['source']})")
    return report, {"order.png": fig, "order.csv": Columns(
        {"order": orders, "amplitude": amp}, {"order": "1/rev", "amplitude": unit})}


def _ordermap_view(record, x, unit, gearbox, freqs, f_sun, speed_range, revs, scale="db"):
    """Order map (order vs rpm) and order cuts of a run-up, from the tachometer or the
    estimated speed (mesh phase)."""
    from ..plotting.views import plot_order_cuts, plot_order_map
    from ..signal.order import order_cuts, order_map

    ang = shaft_angles(record, x, gearbox, f_sun, speed_range)
    if ang["sun"] is None:
        raise opts.OptionError("--preset/--spec", "the tachometer is on the carrier: give the "
                               "gearbox to convert its angle to the input shaft")
    if revs is not None:  # given: at most the revolutions the input shaft makes in the record
        turns = int(abs(float(ang["sun"][-1]) - float(ang["sun"][0])) / (2.0 * np.pi))
        opts.count("--revs", revs, 1, max(turns, 1), "the revolutions of the input shaft in "
                   "the record; each order spectrum needs --revs of them")
    if freqs is not None:
        o = {k: v / freqs["f_sun"] for k, v in freqs.items()}
        mo, pp = o["f_mesh"], o["f_planet_pass"]
        orders = {"fm": mo, "fm − N fc": mo - pp, "fm + N fc": mo + pp, "2fm": 2 * mo}
        max_order = 2.5 * mo
        if revs is None:  # the sidebands fm ± N fc five order bins apart: cuts do not mix
            revs = int(np.ceil(5.0 / pp))
    else:
        orders, max_order = {"1×": 1.0, "2×": 2.0}, 40.0
        revs = revs or 4
    om = order_map(x, record.sample_rate, ang["sun"], max_order=max_order,
                   revs_per_segment=revs)
    cuts = order_cuts(om, orders)
    report = {"angle_source": ang["source"], "revs_per_segment": revs,
              "order_resolution": float(om.orders[1] - om.orders[0]),
              "rpm": {"min": float(om.rpm.min()), "max": float(om.rpm.max())},
              "spectra": int(om.speed.size),
              "order_cuts_max": {k: float(np.nanmax(v)) for k, v in cuts.items()}}
    src = ang["source"]
    return report, {
        "ordermap.png": plot_order_map(om, unit=unit, orders=orders, speed_source=src),
        "ordercuts.png": plot_order_cuts(om, cuts, unit=unit, scale=scale, speed_source=src),
        "ordermap.csv": Grid(("rpm", om.rpm, "1/min"), ("order", om.orders, "1/rev"),
                             ("amplitude", om.amplitude, unit)),
        "ordercuts.csv": Columns({"rpm": om.rpm, "time": om.times,
                                  **{f"order {k}": v for k, v in cuts.items()}},
                                 {"rpm": "1/min", "time": "s",
                                  **{f"order {k}": unit for k in cuts}}),
    }


def _tsa_view(record, x, unit, gearbox, freqs, f_sun, speed_range):
    from ..plotting.views import plot_planet_averages, plot_tsa
    from ..signal.indicators import crest_factor, fm0, fm4, kurtosis, rms
    from ..signal.tsa import planet_separation, sun_relative_angle, time_synchronous_average

    if gearbox is None:
        raise opts.OptionError("--preset/--spec", "the TSA views need the gearbox's tooth counts")
    gs = gearbox.gear_set()
    ang = shaft_angles(record, x, gearbox, f_sun, speed_range)
    carrier = ang["carrier"]
    fs = record.sample_rate
    tsa_c = time_synchronous_average(x, carrier, gs.z_ring * 16, sample_rate=fs)
    rel = sun_relative_angle(carrier, gs.z_sun, gs.z_ring)
    tsa_s = time_synchronous_average(x, rel, gs.z_sun * 16, sample_rate=fs)
    sep = planet_separation(x, carrier, gs.z_ring, gs.z_planet, gs.n_planets, sample_rate=fs)
    planet_fm4 = [float(fm4(np.nan_to_num(a), gs.z_planet)) for a in sep.averages]

    def ind(t, z):
        a = t.average
        return {"n_averages": t.n_averages, "rms": float(rms(a)), "kurtosis": float(kurtosis(a)),
                "crest_factor": float(crest_factor(a)), "fm0": float(fm0(a, z)),
                "fm4": float(fm4(a, z))}

    report = {
        "angle_source": ang["source"],
        "carrier_tsa": ind(tsa_c, gs.z_ring),
        "sun_relative_tsa": ind(tsa_s, gs.z_sun),
        "planets": {
            "numbering": "absolute" if ang["absolute_carrier"] else
                         "relative (carrier angle origin unknown)",
            "window": sep.window, "window_teeth": sep.window_teeth,
            "n_passes": sep.n_passes.tolist(), "complete": sep.complete,
            "fm4": planet_fm4, "largest_fm4": int(np.argmax(planet_fm4)),
        },
    }
    planet_cols = {f"planet_{k}": np.asarray(a) for k, a in enumerate(sep.averages)}
    figs = {
        "tsa.png": plot_tsa(tsa_c, unit=unit, shaft="carrier"),
        "tsa_sun.png": plot_tsa(tsa_s, unit=unit, shaft="sun (relative to the carrier)"),
        "planets.png": plot_planet_averages(sep, planet_fm4, unit=unit),
        "tsa.csv": Columns({"carrier_angle": tsa_c.angle, "average": tsa_c.average},
                           {"carrier_angle": "rad", "average": unit}),
        "tsa_sun.csv": Columns({"sun_angle": tsa_s.angle, "average": tsa_s.average},
                               {"sun_angle": "rad", "average": unit}),
    }
    if planet_cols and len({a.size for a in planet_cols.values()}) == 1:
        figs["planets.csv"] = Columns({"sample": np.arange(next(iter(planet_cols.values())).size),
                                       **planet_cols},
                                      {"sample": "1", **{k: unit for k in planet_cols}})
    return report, figs


def _fault_marks(freqs):
    if freqs is None:
        return None
    return {"fs (sun fault)": freqs["f_sun_fault"], "fp (planet fault)": freqs["f_planet_fault"],
            "fc": freqs["f_carrier"], "N fc": freqs["f_planet_pass"]}


def _envelope_view(record, x, unit, freqs, band, scale="linear"):
    from ..plotting.views import plot_envelope_spectrum
    from ..signal.envelope import envelope_spectrum, fast_kurtogram
    from ..signal.spectrum import level_at

    fs = record.sample_rate
    source = "--band"
    if band is None:
        kg = fast_kurtogram(x, sample_rate=fs)
        band, source = kg.best_band, f"kurtogram (level {kg.best_level:.2f}, K = {kg.best_kurtosis:.2f})"
    f, e = envelope_spectrum(x, band, sample_rate=fs)
    marks = _fault_marks(freqs)
    levels = {k: level_at(f, e, v) for k, v in (marks or {}).items() if v < f[-1]}
    max_f = 4 * max(marks.values()) if marks else min(500.0, float(f[-1]))
    report = {"band_hz": [float(band[0]), float(band[1])], "band_source": source,
              "levels_at_fault_frequencies": levels}
    fig = plot_envelope_spectrum(f, e, band=band, marks=marks, unit=unit, scale=scale,
                                 max_freq=min(max_f, float(f[-1])))
    return report, {"envelope.png": fig, "envelope.csv": Columns(
        {"frequency": f, "amplitude": e}, {"frequency": "Hz", "amplitude": unit})}


def _kurtogram_view(record, x):
    from ..plotting.views import plot_kurtogram
    from ..signal.envelope import fast_kurtogram

    kg = fast_kurtogram(x, sample_rate=record.sample_rate)
    report = {"best_band_hz": list(kg.best_band), "best_level": kg.best_level,
              "best_kurtosis": kg.best_kurtosis, "levels": kg.levels.tolist()}
    return report, {"kurtogram.png": plot_kurtogram(kg), "kurtogram.csv": kurtogram_columns(kg)}


def kurtogram_columns(kg) -> Columns:
    """The kurtogram as a table, one row per band of the 1/3-binary tree: its level, the
    number of bands in that row, the band's index, its edges and centre (Hz, the row's bands
    dividing 0 … Nyquist equally) and its spectral kurtosis."""
    level, n_bands, index, lo, hi, k = [], [], [], [], [], []
    nyq = kg.sample_rate / 2.0
    for r, n in enumerate(np.asarray(kg.n_bands, dtype=int)):
        width = nyq / n
        for j in range(n):
            level.append(float(kg.levels[r]))
            n_bands.append(int(n))
            index.append(j)
            lo.append(j * width)
            hi.append((j + 1) * width)
            k.append(float(kg.kurtosis[r, j]))
    lo_a, hi_a = np.asarray(lo), np.asarray(hi)
    return Columns({"level": np.asarray(level), "n_bands": np.asarray(n_bands),
                    "band": np.asarray(index), "f_low": lo_a, "f_high": hi_a,
                    "f_centre": 0.5 * (lo_a + hi_a), "kurtosis": np.asarray(k)},
                   {"level": "1", "n_bands": "1", "band": "1", "f_low": "Hz", "f_high": "Hz",
                    "f_centre": "Hz", "kurtosis": "1"})


def _cepstrum_view(record, x, freqs, gearbox):
    from ..plotting.views import plot_cepstrum
    from ..signal.cepstrum import rahmonics, real_cepstrum

    q, c = real_cepstrum(x, sample_rate=record.sample_rate)
    spacings = None
    report: dict[str, Any] = {"quefrency_resolution_s": float(q[1])}
    if freqs is not None:
        n = gearbox.gear_set().n_planets
        spacings = {"fc": freqs["f_carrier"], "N fc": freqs["f_planet_pass"],
                    f"fs/{n}": freqs["f_sun_fault"] / n}
        report["rahmonics"] = {k: rahmonics(q, c, v, 3).tolist() for k, v in spacings.items()}
    max_q = 1.5 / min(spacings.values()) if spacings else float(q[-1])
    fig = plot_cepstrum(q, c, spacings=spacings, max_quefrency=min(max_q, float(q[-1])))
    return report, {"cepstrum.png": fig, "cepstrum.csv": Columns(
        {"quefrency": q, "cepstrum": c}, {"quefrency": "s", "cepstrum": "1"})}


def _waterfall_view(record, x, unit, gearbox, freqs, f_sun, speed_range, segment, nat):
    from ..plotting.views import plot_campbell, plot_waterfall
    from ..signal.order import campbell, waterfall

    angle, source = None, None
    if (record.tacho is not None and record.tacho_ppr) or (gearbox is not None and f_sun):
        ang = shaft_angles(record, x, gearbox, f_sun, speed_range)
        angle, source = ang["sun"], ang["source"]
    opts.count("--segment", segment, 16, max(x.size, 16), "samples, the record's length")
    wf = waterfall(x, record.sample_rate, segment_length=segment, angle=angle)
    orders = None
    if freqs is not None:
        mo = freqs["f_mesh"] / freqs["f_sun"]
        orders = {"fm": mo, "2fm": 2 * mo}
    figs = {"waterfall.png": plot_waterfall(wf, unit=unit, orders=orders),
            "waterfall.csv": Grid(("time", wf.times, "s"), ("frequency", wf.freqs, "Hz"),
                                  ("amplitude", wf.amplitude, unit))}
    report: dict[str, Any] = {"segments": int(wf.times.size),
                              "resolution_hz": float(wf.freqs[1] - wf.freqs[0]),
                              "angle_source": source}
    if wf.speed is not None:
        cd = campbell(wf, orders or {"1x": 1.0}, list(nat))
        figs["campbell.png"] = plot_campbell(cd, unit=unit)
        report["speed_hz"] = {"min": float(cd.speed.min()), "max": float(cd.speed.max())}
        report["natural_frequencies_hz"] = cd.natural_frequencies
    return report, figs


def _psd_view(record, x, unit, freqs, band, segment, scale="db"):
    from ..plotting.views import plot_psd
    from ..signal.psd import band_power, welch_psd

    f, p = welch_psd(x, record.sample_rate, segment_length=min(segment, x.size))
    report = {"resolution_hz": float(f[1] - f[0]),
              "rms_total": float(np.sqrt(band_power(f, p, (0.0, float(f[-1])))))}
    if band is not None:
        report["band_hz"] = list(band)
        report["rms_band"] = float(np.sqrt(band_power(f, p, band)))
    marks = {"fm": freqs["f_mesh"], "2fm": 2 * freqs["f_mesh"]} if freqs else None
    return report, {"psd.png": plot_psd(f, p, unit=unit, marks=marks, scale=scale),
                    "psd.csv": Columns({"frequency": f, "psd": p},
                                       {"frequency": "Hz", "psd": f"({unit})^2/Hz"})}


@app.command()
def view(
    record_file: Path = typer.Argument(..., help="Record file (any supported format)."),
    kind: str = typer.Option(..., "--kind", help="order, tsa, envelope, kurtogram, cepstrum, "
                             "waterfall or psd."),
    channel: str = typer.Option("0", "--channel", help="Channel name or index, a comma list, a "
                                "group (a triaxial sensor's name) or 'all': one view each."),
    preset: str | None = opts.preset_option(),
    spec: Path | None = opts.spec_option(),
    f_sun: float | None = typer.Option(None, "--f-sun", help="Input (sun) speed in Hz."),
    band: tuple[float, float] | None = typer.Option(None, "--band",
                                                    help="Band LOW HIGH (Hz): envelope, psd."),
    speed_range: tuple[float, float] | None = typer.Option(
        None, "--speed-range", help="Input-speed range LOW HIGH (Hz) for tacho-less tracking."),
    segment: int = typer.Option(1024, "--segment", parser=opts.whole_number,
                                help="Segment length (samples): waterfall, psd."),
    nat: list[float] | None = typer.Option(None, "--nat", help="Natural frequency (Hz) to overlay "
                                           "on the Campbell diagram (repeatable)."),
    units: str | None = typer.Option(None, "--units", help="Output unit: m/s^2, g, mm/s, um "
                                     "(acceleration integrated behind --highpass); default as "
                                     "recorded."),
    highpass: float = typer.Option(10.0, "--highpass", help="High-pass (Hz) of the integration "
                                   "to mm/s or um (4th-order Butterworth, zero phase)."),
    revs: int | None = typer.Option(None, "--revs", parser=opts.whole_number,
                                    help="ordermap: revolutions per spectrum "
                                    "(order resolution 1/REVS); default: five bins between "
                                    "the planet-pass sidebands (4 without a gearbox)."),
    scale: str | None = typer.Option(None, "--scale", help="db (re the unit's ISO 1683 "
                                     "reference, e.g. 1 µm/s²) or linear; default db, linear "
                                     "for the envelope."),
    sample_rate: float | None = opts.sample_rate_option(),
    json_out: bool = opts.json_option(),
    out: Path | None = opts.out_option("KIND.png (and further PNGs), KIND.csv/.npz, "
                                       "view_KIND.json, report.html"),
    force: bool = opts.export_force_option(),
    export: Path | None = opts.export_option(
        "the view's arrays (with units) to this file: .csv or .npz (the main table: the "
        "carrier TSA, the kurtogram's bands, the spectrum) or .h5/.hdf5 (every table of the "
        "view, one group each)."),
) -> None:
    """Order, TSA, envelope, kurtogram, cepstrum, waterfall or PSD view of a record."""
    opts.choice("--kind", kind, KINDS)
    if export is not None:
        from ..io.export import check_export_path

        check_export_path(export, force=force, inputs=[record_file])
    opts.choice("--scale", scale, ("db", "linear"))
    if units is not None:
        from ..signal import units as units_mod

        if units_mod.normalise_unit(units) is None:
            raise opts.OptionError("--units", f"unknown unit {units!r}; use one of "
                                   f"{', '.join(units_mod.UNITS)}")
    opts.positive("--highpass", highpass, unit="Hz")
    if revs is not None:
        opts.at_least("--revs", revs, 1)
    opts.input_speed_option("--f-sun", f_sun)
    opts.band("--band", band)
    opts.band("--speed-range", speed_range)
    if speed_range is not None and speed_range[0] <= 0:
        raise opts.OptionError("--speed-range", f"LOW must be > 0 Hz, got {speed_range[0]:g}")
    opts.at_least("--segment", segment, 16)
    for v in nat or []:
        opts.positive("--nat", v, unit="Hz")
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec, required=False)
    gearbox = gb.spec if gb is not None else None
    record = opts.read_record(record_file, sample_rate)
    try:
        rows = record.channel_list(channel_token(channel))
    except Exception:  # noqa: BLE001 - one message listing the channels
        opts.check_channel(record, channel_token(channel))
        raise
    fsun, fsun_source = input_speed(record, gearbox, f_sun)
    opts.checked_record(record, rows, gearbox, fsun)
    if band is not None:
        opts.band("--band", band, nyquist=record.sample_rate / 2)
    freqs = gear_frequencies(gearbox, fsun, "paper") if gearbox is not None else None
    from ..io.output import to_jsonable

    reports, figs = [], {}
    for i in rows:
        name, unit = channel_unit(record, i)
        x = np.asarray(record.channel(i), dtype=np.float64)
        if units is not None:
            from ..signal import units as units_mod

            if units_mod.quantity(unit) is None:
                raise opts.OptionError("--units", f"channel {name!r} is in {unit}, not a "
                                       "vibration unit; drop --units")
            x = units_mod.convert_signal(x, record.sample_rate, unit, units,
                                         highpass_hz=highpass)
            unit = units_mod.normalise_unit(units)
        with opts.working(f"{kind} view of {name}"):  # a line on stderr while it runs
            rep, one = _one_view(kind, record, x, unit, gearbox, freqs, fsun, speed_range,
                                 band, segment, nat, revs, scale)
        reports.append({"channel": name, "unit": unit, **rep})
        sfx = "" if len(rows) == 1 else f"_{''.join(c if c.isalnum() or c in '-_' else '_' for c in name)}"
        for fname, v in one.items():
            stem, ext = fname.rsplit(".", 1)
            if len(rows) > 1 and hasattr(v, "axes") and v.axes:  # each figure names its channel
                v.axes[0].set_title(f"{v.axes[0].get_title()} [{name}]")
            figs[f"{stem}{sfx}.{ext}"] = v
    head = {"record": str(record_file), "kind": kind, "f_sun_hz": fsun,
            "f_sun_source": fsun_source}
    report = to_jsonable({**head, **reports[0]} if len(reports) == 1
                         else {**head, "channels": reports})
    if export is not None:
        from ..io.export import export_arrays
        from .logs import note

        sets = {k.rsplit(".", 1)[0]: v for k, v in figs.items() if isinstance(v, (Columns, Grid))}
        if not sets:
            raise opts.OptionError("--export", f"the {kind} view has no arrays to export")
        export_arrays(export, sets, attrs={"record": str(record_file),
                                           "command": f"dtwin view --kind {kind}",
                                           "f_sun_hz": fsun or float("nan")})
        note(f"wrote {export}")
    from ..report.html_report import HTMLReport

    html = HTMLReport(
        title=f"dtwin view --kind {kind}: {Path(record_file).name}",
        summary=dict(_flatten({k: v for k, v in report.items() if k != "channels"},
                              raw=True)),
        figures={f"{k.rsplit('.', 1)[0].replace('_', ' ')}": k for k, v in figs.items()
                 if k.endswith(".png")},
        tables={f"{r['channel']} ({r['unit']})": dict(_flatten(r, raw=True)) for r in reports}
        if len(reports) > 1 else None,
        frequencies=freqs)
    opts.emit(report, json_out=json_out, table=lambda: _print_summary(report), out=out,
              force=force, files={**figs, f"view_{kind}.json": report, "report.html": html},
              inputs=[record_file],
              gearbox=gb, parameters={"kind": kind, "channels": [r["channel"] for r in reports],
                                      "f_sun": fsun, "band": list(band) if band else None})
    if out is None:
        import matplotlib.pyplot as plt

        for fig in figs.values():
            if hasattr(fig, "savefig"):
                plt.close(fig)


def _one_view(kind, record, x, unit, gearbox, freqs, fsun, speed_range, band, segment, nat,
              revs, scale):
    """The report and files of one view of one channel."""
    if kind == "order":
        return _order_view(record, x, unit, gearbox, freqs, fsun, speed_range, scale or "db")
    if kind == "ordermap":
        return _ordermap_view(record, x, unit, gearbox, freqs, fsun, speed_range, revs,
                              scale or "db")
    if kind == "tsa":
        return _tsa_view(record, x, unit, gearbox, freqs, fsun, speed_range)
    if kind == "envelope":
        return _envelope_view(record, x, unit, freqs, band, scale or "linear")
    if kind == "kurtogram":
        return _kurtogram_view(record, x)
    if kind == "cepstrum":
        return _cepstrum_view(record, x, freqs, gearbox)
    if kind == "waterfall":
        return _waterfall_view(record, x, unit, gearbox, freqs, fsun, speed_range, segment,
                               nat or [])
    return _psd_view(record, x, unit, freqs, band, segment, scale or "db")


def _flatten(d: dict, prefix: str = "", raw: bool = False) -> list[tuple[str, Any]]:
    """(key, value) rows of a nested report; floats as text with 5 digits unless `raw`."""
    rows: list[tuple[str, Any]] = []
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            rows.extend(_flatten(v, key + ".", raw))
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            rows.append((key, f"{len(v)} entries (see --json)"))
        elif raw and isinstance(v, (float, int, list)):
            rows.append((key, v))
        elif isinstance(v, float):
            rows.append((key, f"{v:.5g}"))
        else:
            rows.append((key, str(v)))
    return rows


def _print_summary(report: dict) -> None:
    from rich.markup import escape
    from rich.table import Table

    table = Table(title=escape(f"{Path(report['record']).name}: {report['kind']} view, channel "
                               f"{report['channel']}"))
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for k, v in _flatten({k: v for k, v in report.items() if k not in ("record", "kind")}):
        table.add_row(escape(k), escape(v))
    opts.print_table(table)
