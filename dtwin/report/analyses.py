"""The analyses behind the commands, as JSON-ready reports: what ``dtwin freqs``, ``modes``,
``stiffness``, ``spectrum``, ``simulate`` and ``record info`` compute, without the command line.

Each function takes library objects (a :class:`~dtwin.spec.Spec`, lumped parameters, a
:class:`~dtwin.io.record.Record`) and returns plain dicts (and arrays for the figures); the
CLI (:mod:`dtwin.cli`) parses options, calls these, and prints or writes the result. Scripts,
the demo and the notebooks call them directly.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from ..errors import RecordError, SpecError
from ..model.faults import mesh_stiffnesses, parse_fault
from ..model.gears import characteristic_frequencies, geometry_summary
from ..model.modal import frequency_sensitivities, modal_analysis
from ..model.motor.drive import DrivePart
from ..model.motor.shaft import Shaft
from ..model.motor.speed_source import IdealSpeedSource, SpeedProfile
from ..model.stiffness import DOUBLE_CONTACT_FACTOR, single_pair_from_mean
from ..signal.spectrum import (
    FrequencyBasis,
    LabelledPeak,
    amplitude_spectrum,
    find_peaks,
    label_peaks,
    noise_floor,
    time_stats,
)
from ..simulation.simulate import simulate
from ..simulation.speed_range import check_input_speed
from ..spec.build import build_twin, daq_from_spec, operating_speed


def freqs_report(spec: Any, f_sun: float | None, planet_fault: str, source: str) -> dict:
    """JSON-ready result of ``dtwin freqs`` for a loaded :class:`~dtwin.spec.Spec`.

    **Arguments:** `spec`; `f_sun` (Hz) overriding ``operating.f_sun``; `planet_fault`
    convention (``paper`` or ``both_flanks``); `source` label. **Returns:** dict with
    ``source``, ``f_sun_hz``, ``planet_fault``, ``frequencies_hz`` (registry names),
    ``orders`` (frequency / f_sun), ``f_planet_fault_both_flanks_hz`` and ``geometry``.
    """

    if planet_fault not in ("paper", "both_flanks"):
        raise SpecError([("--planet-fault", f"use paper or both_flanks, got {planet_fault!r}")])
    if f_sun is None:
        f_sun = spec["operating"]["f_sun"]
        if f_sun is None:
            raise SpecError([("--f-sun", f"{source} gives no operating.f_sun; pass --f-sun HZ "
                              "(input speed in Hz, e.g. 30 for 1800 rpm)")])
    else:
        f_sun = check_input_speed(f_sun)
    gs = spec.gear_set()
    f = characteristic_frequencies(gs, f_sun, planet_fault=planet_fault)
    both = characteristic_frequencies(gs, f_sun, planet_fault="both_flanks")["f_planet_fault"]
    return {
        "source": source,
        "f_sun_hz": float(f_sun),
        "planet_fault": planet_fault,
        "gears": {"z_sun": gs.z_sun, "z_planet": gs.z_planet, "z_ring": gs.z_ring,
                  "n_planets": gs.n_planets},
        "frequencies_hz": f,
        "orders": {k: v / f_sun for k, v in f.items()},
        "f_planet_fault_both_flanks_hz": both,
        "geometry": geometry_summary(gs),
    }


def operating_mesh_frequency(spec: Any, lp: Any) -> float | None:
    """f_mesh = f_sun Zs Zr / (Zs + Zr) (Hz) at the spec's operating speed, if it gives one."""
    f_sun = spec["operating"].get("f_sun")
    if f_sun is None or not math.isfinite(float(f_sun)) or float(f_sun) <= 0:
        return None
    return float(f_sun) * lp.z_sun * lp.z_ring / (lp.z_sun + lp.z_ring)


def modes_report(lp, model: str, f_mesh: float | None) -> dict[str, Any]:
    """JSON-ready summary: distinct modes with type, multiplicity, sensitivities, mesh order."""
    import numpy as np


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


def _fault_label(f: Any) -> str:
    kind = {"MissingTooth": "missing tooth", "Pitting": "pitting", "RootCrack": "root crack"}
    where = f"planet {f.planet}" if f.location == "planet" else f.location
    return f"{where} tooth {f.tooth} {kind.get(type(f).__name__, type(f).__name__)} {float(f.severity):g}"


def stiffness_curves(
    lp: Any,
    faults: Any = (),
    *,
    n_cycles: float | None = None,
    samples_per_cycle: int = 40,
    n_harmonics: int = 12,
    planet: int = 0,
) -> dict[str, Any]:
    """Planet `planet`'s mesh stiffness under rigid kinematics, healthy and with `faults`.

    The carrier turns from ``-2`` to ``n_cycles + 2`` mesh cycles (``Zr theta_c / 2 pi``), the
    sun at ``theta_c (1 + Zr/Zs)``, the planets at ``theta_c (1 - Zr/Zp)``, the ring fixed.
    `n_cycles` defaults to the tooth count of the faulty gear (``Zs`` without faults).

    **Returns:** dict with ``mesh_cycles`` (T,), ``k_sun_planet``, ``k_ring_planet`` (healthy,
    N/m) and, with faults, ``k_sun_planet_faulty``, ``k_ring_planet_faulty`` (N/m), all numpy.
    """
    import jax
    import jax.numpy as jnp
    import numpy as np


    if n_cycles is None:
        z = {"sun": lp.z_sun, "planet": lp.z_planet, "ring": lp.z_ring}
        n_cycles = max([lp.z_sun] + [z[f.location] for f in faults])
    x = np.arange(-2.0, n_cycles + 2.0, 1.0 / samples_per_cycle)
    tc = jnp.asarray(x * 2 * np.pi / lp.z_ring, dtype=jnp.float64)
    ts = tc * (1.0 + lp.z_ring / lp.z_sun)
    tp = jnp.broadcast_to((tc * (1.0 - lp.z_ring / lp.z_planet))[:, None],
                          (tc.shape[0], lp.n_planets))
    tr = jnp.zeros_like(tc)

    def run(fs):
        f = jax.vmap(lambda a, b, c, d: mesh_stiffnesses(lp, a, b, c, d, fs,
                                                         n_harmonics=n_harmonics))
        k_sp, k_rp = f(ts, tc, tr, tp)
        return np.asarray(k_sp[:, planet]), np.asarray(k_rp[:, planet])

    out: dict[str, Any] = {"mesh_cycles": x}
    out["k_sun_planet"], out["k_ring_planet"] = run(())
    if faults:
        out["k_sun_planet_faulty"], out["k_ring_planet_faulty"] = run(tuple(faults))
    return out


def stiffness_report(lp: Any, faults: Any, curves: dict[str, Any]) -> dict[str, Any]:
    """JSON-ready summary: per mesh k_mean, c', 1.75 c', eps and the faulty extremes (N/m)."""
    import numpy as np


    meshes = {}
    for name, k, eps, key in (("sun_planet", lp.k_sun_planet, lp.eps_sp, "k_sun_planet"),
                              ("ring_planet", lp.k_ring_planet, lp.eps_rp, "k_ring_planet")):
        c1 = float(single_pair_from_mean(k, eps))
        row = {"k_mean": float(k), "c_single": c1, "c_double": DOUBLE_CONTACT_FACTOR * c1,
               "eps": float(eps), "k_min_healthy": float(np.min(curves[key])),
               "k_max_healthy": float(np.max(curves[key]))}
        if faults:
            kf = curves[key + "_faulty"]
            row["k_min_faulty"] = float(np.min(kf))
            row["max_loss"] = float(np.max(curves[key] - kf))
        meshes[name] = row
    return {
        "z_sun": lp.z_sun, "z_planet": lp.z_planet, "z_ring": lp.z_ring,
        "n_planets": lp.n_planets, "meshes": meshes,
        "faults": [{"label": _fault_label(f), "type": type(f).__name__, "location": f.location,
                    "tooth": f.tooth, "planet": f.planet, "flank": f.flank,
                    "severity": float(f.severity), "meaning": f.severity_meaning}
                   for f in faults],
    }


def operating_point(record, spec, f_sun: float | None, *, channel: int | str = 0):
    """The input (sun) speed of `record` by the one rule of
    :func:`dtwin.identify.operating_point.resolve_speed`: `f_sun` (``--f-sun``) → the record's
    tachometer → its metadata ``f_sun`` → its mesh lines (`channel`; needs `spec`) → the
    spec's ``operating.f_sun``. A speed the lines contradict is used with a warning naming the
    lines; when the mesh harmonics disagree with each other, the spec's speed is used with a
    warning. **Returns:** the :class:`~dtwin.identify.operating_point.OperatingPoint` (speed,
    uncertainty, source, lines used), None when nothing gives a speed."""
    # dtwin.identify (fits, JAX programs) is imported when a record's speed is resolved only
    from dtwin.identify.operating_point import (
        OperatingPoint,
        SpeedDisagreementError,
        SpeedWarning,
        nominal_speed,
        resolve_speed,
    )

    try:
        return resolve_speed(record, spec, f_sun, channel=channel, required=False)
    except SpeedDisagreementError as e:
        nominal = nominal_speed(spec)
        if not nominal:
            raise
        note = f"{e}; the spec's operating.f_sun ({nominal:g} Hz) is used"
        warnings.warn(note, SpeedWarning, stacklevel=2)
        f = check_input_speed(nominal, "operating.f_sun")
        return OperatingPoint(f, float("nan"), 0.0, "spec", source="spec operating.f_sun",
                              note=note)


def input_speed(record, spec, f_sun: float | None, *,
                channel: int | str = 0) -> tuple[float | None, str | None]:
    """Input (sun) speed (Hz) of `record` and where it came from (:func:`operating_point`);
    ``(None, None)`` when nothing gives a speed."""
    op = operating_point(record, spec, f_sun, channel=channel)
    return (None, None) if op is None else (op.f_sun, op.source)


def gear_frequencies(spec, f_sun: float | None, planet_fault: str = "paper") -> dict | None:
    """Characteristic frequencies (Hz) from :func:`dtwin.model.gears.characteristic_frequencies`."""
    if spec is None:
        return None
    if f_sun is None:
        raise SpecError([("--f-sun", "the input speed is unknown: pass --f-sun HZ, give the "
                          "record a tachometer, or use a spec with operating.f_sun")])

    return characteristic_frequencies(spec.gear_set(), f_sun, planet_fault=planet_fault)


def channel_unit(record, channel: str | int) -> tuple[str, str]:
    i = record.index(channel)
    return record.channels[i], record.units[i] or "-"


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
    welch: tuple[int, float] | None = None,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Spectrum, peaks and labels of one channel of a :class:`dtwin.io.Record`.

    **Arguments:** `frequencies`: characteristic frequencies (Hz, registry names) to label with,
    or None (peaks unlabelled); `n_planets` for the "fs/N" labels; `welch`: ``(segment
    samples, overlap fraction)`` for a Welch-averaged amplitude spectrum
    (:func:`dtwin.signal.psd.averaged_amplitude_spectrum`), None for one FFT of the whole record; the
    rest as :func:`dtwin.signal.spectrum.find_peaks`.

    **Returns:** ``(report, data)``: the JSON-ready report and the arrays for the figures
    (``freqs``, ``spec``, ``floor``, ``labelled``, ``t``, ``x``, ``unit``).
    """

    name, unit = channel_unit(record, channel)
    nyq = record.sample_rate / 2
    if not 0 <= band[0] < band[1] <= nyq:
        raise RecordError(f"--band {band[0]:g} {band[1]:g} must satisfy 0 <= low < high <= "
                          f"{nyq:g} Hz (half the record's sampling rate)")
    x = record.channel(channel)
    if not np.all(np.isfinite(x)):
        raise RecordError(f"channel {name!r} holds NaN or inf samples; clean the record first")
    if welch is None:
        freqs, spec = amplitude_spectrum(x, record.sample_rate, window)
    else:
        # scipy.signal (Welch) only when an averaged spectrum is asked for: not at `dtwin --help`
        from ..signal.psd import averaged_amplitude_spectrum

        freqs, spec = averaged_amplitude_spectrum(x, record.sample_rate, window,
                                                  segment_length=int(welch[0]),
                                                  overlap=float(welch[1]))
    floor = noise_floor(spec, floor_width)
    peaks = find_peaks(freqs, spec, threshold_db=threshold_db, min_spacing_hz=min_spacing_hz,
                       band=band, floor=floor, max_peaks=max_peaks)
    df = float(freqs[1] - freqs[0])
    withheld = None
    if frequencies is not None and df > float(frequencies["f_carrier"]):
        # a label is matched within one bin: bins wider than the carrier sideband spacing
        # would fit some label to any peak
        withheld = (f"resolution {df:.4g} Hz is coarser than the carrier frequency "
                    f"{float(frequencies['f_carrier']):.4g} Hz: the peaks are not labelled; "
                    f"use a record longer than {1.0 / float(frequencies['f_carrier']):.3g} s")
    if frequencies is not None and withheld is None:
        basis = FrequencyBasis(frequencies["f_mesh"], frequencies["f_carrier"],
                               frequencies.get("f_sun_fault"), frequencies.get("f_planet_fault"),
                               n_planets)
        labelled = label_peaks(peaks, basis, df)
    else:

        labelled = [LabelledPeak(k, p, ()) for k, p in enumerate(peaks, start=1)]
    stats = time_stats(x)
    sel = (freqs >= band[0]) & (freqs <= band[1])
    report = {
        "channel": name,
        "unit": unit,
        "sample_rate_hz": float(record.sample_rate),
        "duration_s": float(record.duration),
        "window": window,
        "averaging": ({"method": "welch", "segment_samples": int(welch[0]),
                       "overlap": float(welch[1])} if welch is not None else None),
        "band_hz": [float(band[0]), float(band[1])],
        "resolution_hz": df,
        "noise_floor_median": float(np.median(floor[sel])) if sel.any() else None,
        "threshold_db": threshold_db,
        "time_stats": {"rms": float(stats.rms), "kurtosis": float(stats.kurtosis),
                       "crest_factor": float(stats.crest_factor)},
        "frequencies_hz": frequencies,
        "labels_withheld": withheld,
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


    f = check_input_speed(operating_speed(spec) if f_sun is None else f_sun)
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


def record_report(rec: Any, problems: list[Any], freqs: dict[str, float]) -> dict[str, Any]:
    """JSON-ready summary of a record: channels with statistics, rate, duration, problems."""
    chans = []
    for i, name in enumerate(rec.channels):
        x = rec.data[i]
        finite = x[np.isfinite(x)]
        stats = ({"min": float(finite.min()), "max": float(finite.max()),
                  "mean": float(finite.mean()), "rms": float(np.sqrt(np.mean(finite**2)))}
                 if finite.size else {"min": None, "max": None, "mean": None, "rms": None})
        chans.append({"name": name, "unit": rec.units[i], **stats,
                      "problems": [p.kind for p in problems if p.channel == name]})
    return {
        "file": rec.metadata.get("source"),
        "format": rec.metadata.get("format"),
        "sample_rate_hz": float(rec.sample_rate),
        "n_samples": rec.n_samples,
        "duration_s": rec.duration,
        "channels": chans,
        "groups": {k: list(v) for k, v in rec.groups.items()},
        "tacho": None if rec.tacho is None else {
            "channel": rec.metadata.get("tacho_channel") or "tacho", "ppr": rec.tacho_ppr,

            "shaft": rec.tacho_shaft},
        "frequencies_hz": freqs,
        "problems": [{"kind": p.kind, "channel": p.channel, "sample": p.sample,
                      "value": p.value, "message": p.message} for p in problems],
        "metadata": rec.metadata,
    }


__all__ = [
    "channel_unit", "freqs_report", "gear_frequencies", "input_speed", "modes_report",
    "operating_mesh_frequency", "operating_point",
    "record_report", "run_simulation", "spectrum_report", "stiffness_curves", "stiffness_report",
]
