"""Why a fault depth comes out wrong: the loss along the depth, per twin kind, on a family record.

For a tooth-fault record of a gearbox in ``../shared/independent/`` (its truth in
``truth.json``) and a calibrated spec of that machine (``benchmarks/family.py`` writes one per
machine into ``benchmarks/out/family/<machine>/calibration/``), this builds the problem
``dtwin severity`` fits (:func:`dtwin.identify.fit.make_problem` with the fault free, the low
band added for a sun or ring fault as :mod:`dtwin.identify.severity` does) with each twin kind,
and evaluates, with nothing else refitted:

- the loss ``‖r‖²`` along the fault's depth (a grid of severities, each also given as the peak
  stiffness loss relative to the mean mesh stiffness: the truth's terms), and where it is
  least;
- the same loss per band of the observation (band 0: the low band; band m: the m-th mesh
  band), so that one can read which lines pull the depth where;
- with ``--splits``, all of it again for the other end of the calibration's
  excitation/response split (:func:`dtwin.identify.excitation_response.stiffness_split`), which ``dtwin
  severity`` fits too.

- with ``--signature``, the fault's signature measured against predicted, per band: the twin
  (each kind, the calibrated spec) simulated healthy and with the fault at the true depth and at
  the depth of least loss, and in the record and in the twin the power the fault adds over the
  healthy spectrum on the fault's lines (the bins where the faulty record stands 12 dB over the
  healthy record's noise floor and 6 dB over the healthy record itself; the machine's healthy
  record is ``baseline-1``), relative to the band's healthy power, in dB. The healthy band power
  of the twin against the record's is given too: a band the healthy twin misses by many dB
  cannot weigh a fault's sidebands right. The excitation, window and response cancel in the
  ratio (they act alike on the healthy and the faulty lines of one band), so what is left is
  the fault's own dynamics: how loud the twin makes a given loss of stiffness.

A kind whose least loss lies far from the truth while the other's lies near it is a model-form
cause (the twin's dynamics), not an estimator's; both far from it points at the excitation or
the response. One line per grid point on stderr, a JSON summary on stdout.

Usage::

    python benchmarks/fault_depth.py --machine mcfadden-19-38-95 --record sun-fault-b \\
        --spec benchmarks/out/family/mcfadden-19-38-95/calibration/calibrated.toml \\
        [--kinds torsional translational] [--points 12] [--signature]
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
from family import FAULT_LOCATION, effect_kind, machines


def _loss_profile(record, spec, location: str, kind: str, peaks: np.ndarray) -> dict:
    import jax.numpy as jnp

    from dtwin.identify.fit import make_problem
    from dtwin.identify.low_band import LOW_BAND_LOCATIONS, with_low_band_problem
    from dtwin.identify.residuals import point_groups
    from dtwin.identify.severity import _fault_index, _name, _peak
    from dtwin.identify.solve import batched_residuals
    from dtwin.model.faults import severity_for_peak_loss

    name = _name(location)
    problem, _ = make_problem(record, spec, [name], kind=kind, initial={name: 0.1})
    if location in LOW_BAND_LOCATIONS:
        problem = with_low_band_problem(problem, record)
    i = _fault_index(problem.twin, location)
    fault = problem.twin.parts[i].fault
    sev = np.array([severity_for_peak_loss(fault, problem.twin.lp, float(p)) for p in peaks])
    sev = np.clip(sev, 1e-4, 1.0)
    thetas = jnp.asarray(np.stack([problem.pset.theta([s]) for s in sev]))
    t0 = time.perf_counter()
    r = np.asarray(batched_residuals(thetas, problem, "map"))
    wall = time.perf_counter() - t0
    n_prior = len(problem.pset.priors)
    groups = point_groups(problem.observations)
    data = r[:, : r.shape[1] - n_prior] if n_prior else r
    loss = np.sum(data**2, axis=1)
    per_band = {int(g): np.sum(data[:, groups == g] ** 2, axis=1).tolist()
                for g in np.unique(groups)}
    peak_of = [float(_peak(problem.twin, i, s)) for s in sev]
    for p, s, pk, lo in zip(peaks, sev, peak_of, loss, strict=True):
        print(f"{kind:13s} peak {p:5.3f} (severity {s:.4f}, reported {pk:5.3f}) loss {lo:10.2f}",
              file=sys.stderr, flush=True)
    return dict(kind=kind, peaks=peaks.tolist(), severity=sev.tolist(), loss=loss.tolist(),
                loss_per_band=per_band, best_peak=float(peaks[int(np.argmin(loss))]),
                wall_s=wall)


def _bands(spec, f_sun: float, fs: float) -> list[tuple[str, float, float]]:
    """The low band (``0.8 N f_c`` to ``f_m / 2``, as severity's) and the mesh bands
    ``(m ± 1/2) f_m`` below the DAQ's pass band (``0.45 fs``;
    :func:`dtwin.identify.line_ratio.mesh_bands`), in Hz."""
    from dtwin.identify.line_ratio import mesh_bands

    g = spec["gears"]
    fc = f_sun * g["z_sun"] / (g["z_sun"] + g["z_ring"])
    fm = g["z_ring"] * fc
    return [("low", 0.8 * g["n_planets"] * fc, 0.5 * fm), *mesh_bands(fm, fs)]


def _power(record) -> tuple[np.ndarray, np.ndarray]:
    """Hann-windowed power spectrum of a record's first channel
    (:func:`dtwin.identify.line_ratio.power_spectrum`): (Hz, power)."""
    from dtwin.identify.line_ratio import power_spectrum

    x = np.asarray(record.data)
    x = x.reshape(-1) if min(x.shape) == 1 else x[0]
    return np.fft.rfftfreq(x.size, 1.0 / record.sample_rate), power_spectrum(x)


def twin_power(spec, lp, location: str, kind: str, peak: float, duration: float,
               sample_rate: float) -> tuple[np.ndarray, np.ndarray]:
    """The calibrated twin's power spectrum (:func:`_power`), healthy for `peak` 0, else with
    the twin's default fault (a sharp missing tooth) at `location` of peak stiffness loss `peak`
    (the truth's terms), simulated for `duration` (s) at `sample_rate` (Hz) without noise."""
    from dtwin.model.faults import make_fault, severity_for_peak_loss
    from dtwin.report.analyses import run_simulation

    faults = None
    if peak:
        sev = severity_for_peak_loss(make_fault("missing_tooth", location, 0.5), lp, peak)
        faults = [f"{location}:missing_tooth:{sev}"]
    rec, _, _ = run_simulation(spec, faults=faults, kind=kind, duration=duration,
                               sample_rate=sample_rate, snr_db=80.0)
    return _power(rec)


def _excess_db(faulty: np.ndarray, healthy: np.ndarray, lines: np.ndarray) -> float:
    """Power `faulty` adds over `healthy` on the bins `lines`, relative to the healthy band's
    power (dB; −inf when it adds none)."""
    e = float(np.sum(np.clip(faulty - healthy, 0.0, None)[lines]))
    return float(10 * np.log10(e / np.sum(healthy))) if e > 0 else float("-inf")


def _signature(folder, record, spec_path, location: str, kind: str, peaks: dict) -> dict:
    """The fault's signature per band (module docstring, ``--signature``): record against
    the twin at each depth of `peaks` (label → peak stiffness loss, the truth's terms)."""
    from scipy.ndimage import median_filter

    from dtwin.io.readers import read_record
    from dtwin.spec import load_spec
    from dtwin.spec.build import build_twin

    spec = load_spec(spec_path)
    lp = build_twin(spec, kind=kind).lp
    healthy = read_record(folder / "baseline-1.csv")
    fs = float(record.sample_rate)
    f_r, p_rf = _power(record)
    _, p_rh = _power(healthy)
    floor = median_filter(p_rh, size=31, mode="nearest")

    def twin(peak):
        return twin_power(spec, lp, location, kind, peak, record.duration, fs)

    f_t, p_th = twin(0.0)
    p_tf = {k: twin(v)[1] for k, v in peaks.items()}
    rows = []
    for name, lo, hi in _bands(spec, float(spec["operating"]["f_sun"]), fs):
        sel_r = (f_r >= lo) & (f_r < hi)
        sel_t = (f_t >= lo) & (f_t < hi)
        # the fault's lines: bins of the faulty record 12 dB over the healthy record's floor
        # and 6 dB over its bin (two noise bins' ratio passes 6 dB alone one time in five)
        lines = (p_rf[sel_r] > 10 ** 1.2 * floor[sel_r]) & (p_rf[sel_r] > 4.0 * p_rh[sel_r])
        n = min(lines.size, int(sel_t.sum()))
        lines, h_r = lines[:n], p_rh[sel_r][:n]
        h_t = p_th[sel_t][:n]

        row = dict(band=name, lo_hz=lo, hi_hz=hi, bins=int(lines.sum()),
                   record_db=_excess_db(p_rf[sel_r][:n], h_r, lines),
                   healthy_twin_vs_record_db=float(10 * np.log10(h_t.sum() / h_r.sum())))
        for k, p in p_tf.items():
            row[f"twin_{k}_db"] = _excess_db(p[sel_t][:n], h_t, lines)
        rows.append(row)
        print(f"{kind:13s} {name:7s} {int(lines.sum()):4d} bins: record {row['record_db']:7.2f}"
              + "".join(f"  twin@{k} {row[f'twin_{k}_db']:7.2f}" for k in p_tf)
              + f"  (healthy twin/record {row['healthy_twin_vs_record_db']:+6.2f}) dB",
              file=sys.stderr, flush=True)
    return dict(kind=kind, peaks=peaks, bands=rows)


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--machine", required=True)
    p.add_argument("--record", required=True)
    p.add_argument("--spec", required=True, help="the machine's calibrated spec")
    p.add_argument("--kinds", nargs="*", default=["torsional", "translational"])
    p.add_argument("--points", type=int, default=12)
    p.add_argument("--splits", action="store_true",
                   help="also the other end of the calibration's excitation/response split "
                        "(dtwin.identify.split.stiffness_split), as dtwin severity fits both")
    p.add_argument("--signature", action="store_true",
                   help="also the fault's signature per band, record against the twin at the "
                        "true depth and at the depth of least loss (module docstring)")
    args = p.parse_args(argv)
    from dtwin.io.readers import read_record

    folder = machines()[args.machine]
    truth = json.loads((folder / "truth.json").read_text())["records"][args.record]
    eff = truth["effects"][0]
    location = FAULT_LOCATION[effect_kind(eff)]
    true_peak = float(eff.get("peak_stiffness_loss", float("nan")))
    peaks = np.unique(np.concatenate([np.geomspace(0.01, 0.9, args.points), [true_peak]]))
    peaks = peaks[np.isfinite(peaks)]
    record = read_record(folder / f"{args.record}.csv")
    out = dict(machine=args.machine, record=args.record, location=location,
               true_peak=true_peak, kinds=[])
    from dtwin.identify.excitation_response import (
        SPLIT_CALIBRATED,
        SPLIT_STIFFNESS,
        stiffness_split,
    )

    specs = [(SPLIT_CALIBRATED, args.spec)]
    if args.splits and stiffness_split(args.spec) is not None:
        specs.append((SPLIT_STIFFNESS, stiffness_split(args.spec)))
    for kind in args.kinds:
        for split, spec in specs:
            print(f"-- {kind}, {split}", file=sys.stderr, flush=True)
            row = _loss_profile(record, spec, location, kind, peaks)
            out["kinds"].append(dict(row, split=split))
            if args.signature and split == SPLIT_CALIBRATED:
                out.setdefault("signature", []).append(_signature(
                    folder, record, spec, location, kind,
                    {"truth": true_peak, "least_loss": row["best_peak"]}))
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
