"""A fault's depth read from the ratio of its lines to the healthy lines, band by band.

A prototype estimator, for comparing with ``dtwin severity`` on the independent family
(``../shared/independent/``, truth in ``truth.json``), not a product path. Within one band of
the **faulty** record, the power the fault adds on its lines (over the healthy record's) over
the power on the gearbox's healthy lines is a ratio in which the calibration's excitation,
window and response cancel (both kinds of line pass the same path at nearly the same
frequency), and so does any gain. The twin (each kind, the machine's calibrated spec) is
simulated healthy and with the fault at a few depths, the same ratio taken on the same bins
(the excess over the healthy twin), and the depth at which the twin's ratio meets the record's is
read by interpolation in log-depth (held at the grid's ends). Bins: the fault's lines are the
bins of the faulty record 12 dB over the healthy record's noise floor (a 31-bin running
median of ``baseline-1``) and 6 dB over the healthy record itself; the healthy lines, the bins
of ``baseline-1`` 12 dB over its floor. Depths are peak stiffness loss in the truth's terms (the
fault's instantaneous loss at its peak; ``reference="instant"`` of
:func:`dtwin.model.faults.peak_stiffness_loss`).

Usage (one line per record on stdout; the calibrations as ``benchmarks/family.py`` writes
them, ``<calibrations>/<machine>/calibration/calibrated.toml``)::

    python benchmarks/sideband_ratio.py --calibrations benchmarks/out/family \\
        --kind translational original:sun-fault-0.60 four-planet-20-30-80:sun-fault-a
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np
from family import FAULT_LOCATION, effect_kind, machines
from fault_depth import _bands, _power, twin_power

#: Peak stiffness losses (the truth's terms) the twin is simulated at.
DEPTHS = (0.05, 0.15, 0.4, 0.9)


def _selections(f, p_fault, p_healthy, bands):
    """Per band: (the fault's line bins, the healthy line bins) (module docstring)."""
    from scipy.ndimage import median_filter

    floor = median_filter(p_healthy, size=31, mode="nearest")
    out = {}
    for name, lo, hi in bands:
        s = (f >= lo) & (f < hi)
        out[name] = (s & (p_fault > 10 ** 1.2 * floor) & (p_fault > 4.0 * p_healthy),
                     s & (p_healthy > 10 ** 1.2 * floor))
    return out


def _ratios(p, p_healthy, sel) -> dict[str, float]:
    """Per band, the power `p` adds over `p_healthy` on the fault's lines, over the power of
    `p` on the healthy lines (dB; NaN where a set is empty or nothing is added). The excess,
    not the power: a ring fault's lines ``k N f_c`` and ``m f_m ± k N f_c`` lie on the
    healthy gearbox's own planet-pass lines."""
    out = {}
    for n, (a, b) in sel.items():
        e = float(np.clip(p - p_healthy, 0.0, None)[a].sum())
        out[n] = 10 * np.log10(e / p[b].sum()) if a.any() and b.any() and e > 0 else np.nan
    return out


def depth_from_ratio(record_db: float, twin_db: np.ndarray, depths=DEPTHS) -> float:
    """The depth at which the twin's ratios `twin_db` (dB, one per depth of `depths`) meet the
    record's `record_db`, interpolated in log-depth and held at the grid's ends."""
    order = np.argsort(twin_db)
    return float(np.exp(np.interp(record_db, np.asarray(twin_db)[order],
                                  np.log(np.asarray(depths))[order])))


def estimate(machine: str, record: str, calibrations: pathlib.Path, kind: str,
             bands=("low", "mesh1", "mesh2")) -> dict:
    """The record's and the twin's ratios per band and the depth each band reads."""
    from dtwin.io.readers import read_record
    from dtwin.spec import load_spec
    from dtwin.spec.build import build_twin

    folder = machines()[machine]
    effect = json.loads((folder / "truth.json").read_text())["records"][record]["effects"][0]
    location = FAULT_LOCATION[effect_kind(effect)]
    spec = load_spec(calibrations / machine / "calibration" / "calibrated.toml")
    lp = build_twin(spec, kind=kind).lp
    rec = read_record(folder / f"{record}.csv")
    f, p_fault = _power(rec)
    _, p_healthy = _power(read_record(folder / "baseline-1.csv"))
    fs = float(rec.sample_rate)
    chosen = [b for b in _bands(spec, float(spec["operating"]["f_sun"]), fs) if b[0] in bands]
    sel = _selections(f, p_fault, p_healthy, chosen)
    measured = _ratios(p_fault, p_healthy, sel)

    def simulated(depth):
        return twin_power(spec, lp, location, kind, depth, rec.duration, fs)[1]

    p_twin_healthy = simulated(0.0)
    twin = [_ratios(simulated(d), p_twin_healthy, sel) for d in DEPTHS]
    rows = {}
    for n in sel:
        y = np.array([t[n] for t in twin])
        ok = np.isfinite(measured[n]) and np.all(np.isfinite(y))
        rows[n] = dict(record_db=measured[n], twin_db=y.tolist(),
                       depth=depth_from_ratio(measured[n], y) if ok else None)
    return dict(machine=machine, record=record, kind=kind,
                truth=float(effect.get("peak_stiffness_loss", np.nan)), bands=rows)


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("cases", nargs="+", help="MACHINE:RECORD (a tooth-fault record)")
    p.add_argument("--calibrations", type=pathlib.Path, default=pathlib.Path(
        "benchmarks/out/family"), help="folder holding <machine>/calibration/calibrated.toml")
    p.add_argument("--kind", default="translational", choices=("translational", "torsional"))
    args = p.parse_args(argv)
    for case in args.cases:
        machine, record = case.split(":")
        row = estimate(machine, record, args.calibrations, args.kind)
        print(json.dumps(row), flush=True)
        print(f"{args.kind:13s} {machine:22s} {record:15s} truth {row['truth']:.2f} | "
              + " | ".join(f"{n}: " + ("n/a" if b["depth"] is None else f"{b['depth']:.3f}")
                           for n, b in row["bands"].items()), file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
