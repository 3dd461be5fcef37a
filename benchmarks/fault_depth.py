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

A kind whose least loss lies far from the truth while the other's lies near it is a model-form
cause (the twin's dynamics), not an estimator's; both far from it points at the excitation or
the response. One line per grid point on stderr, a JSON summary on stdout.

Usage::

    python benchmarks/fault_depth.py --machine mcfadden-19-38-95 --record sun-fault-b \\
        --spec benchmarks/out/family/mcfadden-19-38-95/calibration/calibrated.toml \\
        [--kinds torsional translational] [--points 12]
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
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
