"""Whether a fitted parameter is confounded with what calibration fitted.

A calibrated spec (``dtwin calibrate``, :mod:`dtwin.identify.calibrate`) carries the mesh
excitation as transmission-error harmonics in metres
(:class:`dtwin.parts.mesh_excitation.MeshExcitation`), fitted from healthy records with the
mesh stiffnesses, damping and inertias held at the spec's values. Below the mesh modes the
dynamic mesh force a transmission error ``e`` drives is close to ``k e`` (``k`` the mesh
stiffness in series with the bodies' compliance), so what a record of a few kHz measures is
that product. A later fit that frees a stiffness with the calibrated excitation held reads
the product as the stiffness: it finds a value, with an interval that only says how well the
product is known. Had calibration been run at that stiffness, the excitation would have
come out different and the fit would have found no reason to move. The record alone cannot
tell the stiffness from the excitation; the interval claims it can.

**The check** (:func:`calibration_confounding`). At the optimum the free parameters are
joined by the calibrated excitation harmonics (``excitation_<mesh>_<cos|sin>_<h>``, those the
spec carries nonzero), the Jacobian is taken again and the same analysis
(:func:`dtwin.identify.uncertainty.analyse`: sandwich covariance, lack-of-fit widening, the
half-width and near-null rules) is repeated with them free, without a prior (the calibration
fitted them at the spec's stiffness, so its intervals do not hold at another). A parameter
determined with the excitation held and not with it free is flagged NOT DETERMINED, and the
flag gives the interval it has with the excitation free. A parameter whose signature the
excitation cannot reproduce (a tooth fault's sidebands and comb) keeps its interval.

The check runs when the spec is calibrated and a free parameter is one calibration held at
the spec's value while it fitted the excitation: the mesh and support stiffnesses, damping
ratios, masses and inertias, and a transmission-error amplitude on top of the calibrated one
(registry sections ``mesh``, ``supports``, ``damping``, ``lumped``). It costs one forward-mode Jacobian with a column per free parameter and per
calibrated harmonic.

The calibrated load shares (``imperfections.load_sharing``, turned into mesh clearances at the
spec's stiffness by :func:`dtwin.parts.imperfections.load_share_offsets`) are a second such
path; they have no address in a twin (a share is a clearance only through the static balance),
so they are not among the columns.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from dtwin.registry import N_EXCITATION_HARMONICS, lookup

from .params import ParameterSet
from .uncertainty import Uncertainty, analyse

__all__ = ["CONFOUNDABLE_SECTIONS", "calibrated_excitation", "calibration_confounding",
           "needs_check"]

#: Registry sections (first part of a parameter's spec path) of the parameters calibration
#: holds at the spec's values while it fits the excitation.
CONFOUNDABLE_SECTIONS = ("mesh", "supports", "damping", "lumped")


def calibrated_excitation(spec) -> tuple[str, ...]:
    """Registry names of the transmission-error harmonics a calibrated spec carries (the
    ``[mesh] excitation_<mesh>_<cos|sin>`` arrays of a mesh type with any nonzero value, up to
    the registry's ``N_EXCITATION_HARMONICS``); empty for a spec without ``[calibration]``."""
    if spec["calibration"]["records"] is None:
        return ()
    mesh = spec["mesh"]
    out = []
    for m in ("sun", "ring"):
        arrays = [mesh.get(f"excitation_{m}_{cs}") or () for cs in ("cos", "sin")]
        if not any(float(v) != 0.0 for a in arrays for v in a):
            continue
        n = min(max(len(a) for a in arrays), N_EXCITATION_HARMONICS)
        out += [f"excitation_{m}_{cs}_{h}" for cs in ("cos", "sin") for h in range(1, n + 1)]
    return tuple(out)


def _confoundable(name: str) -> bool:
    info = lookup(name)
    return (info.spec_path.split(".")[0] in CONFOUNDABLE_SECTIONS
            and not name.startswith("excitation_"))


def needs_check(free, spec) -> bool:
    """Whether :func:`calibration_confounding` applies: `spec` is calibrated, carries an
    excitation, and one of the `free` names is a parameter calibration held fixed."""
    return bool(calibrated_excitation(spec)) and any(_confoundable(n) for n in free)


def calibration_confounding(problem, theta, unc: Uncertainty, spec, *, groups, expected_rss,
                            jacobian) -> tuple[Uncertainty, dict[str, tuple[float, float]]]:
    """`unc` with the parameters that the calibrated excitation confounds flagged (module
    docstring).

    **Arguments:** `problem` (:class:`dtwin.identify.fit.Problem`) and its optimum `theta`;
    `unc`: the analysis with the excitation held; `spec`: the calibrated spec; `groups`,
    `expected_rss`: as for :func:`dtwin.identify.uncertainty.analyse`; `jacobian(theta,
    problem) -> (r, J)`: the residuals and forward-mode Jacobian of a problem.

    **Returns:** ``(unc, intervals)``: the analysis with the new flags added to
    ``not_determined``, and the 95 % interval (SI) of every free parameter with the excitation
    free.
    """
    pset = problem.pset
    nuisance = [n for n in calibrated_excitation(spec) if n not in pset.free]
    if not nuisance:
        return unc, {}
    values = pset.as_dict(theta)
    # every free parameter starting at its fitted value, the excitation at the calibrated one
    # (read from the twin): the joint set's θ is 0 at the optimum
    joint = ParameterSet.build(
        list(pset.free) + nuisance, problem.twin, initial=values, fixed=dict(pset.fixed),
        bounds={n: (lo, hi) for n, lo, hi in zip(pset.free, pset.lower, pset.upper,
                                                  strict=True)},
        priors={n: (m, s) for n, m, s in pset.priors})
    prob = type(problem)(joint.prepare(problem.twin), joint, problem.observations,
                         rtol=problem.rtol, atol=problem.atol, adjoint="forward",
                         periodic=problem.periodic)
    r, J = jacobian(jnp.zeros(joint.size), prob)
    wide = analyse(joint, np.zeros(joint.size), np.asarray(r), np.asarray(J), groups,
                   n_profiled_gains=problem.n_profiled_gains, expected_rss=expected_rss)
    intervals = {n: (float(wide.interval[i, 0]), float(wide.interval[i, 1]))
                 for i, n in enumerate(pset.free)}
    flags = dict(unc.not_determined)
    h = len(nuisance) // 2
    for n in pset.free:
        if n in flags or n not in wide.not_determined:
            continue
        lo, hi = intervals[n]
        flags[n] = (f"confounded with the calibrated mesh excitation ({h} transmission-error "
                    f"harmonics fitted at the spec's values): with it free, "
                    f"{wide.not_determined[n]}; 95 % interval [{lo:.4g}, {hi:.4g}]")
    return dataclasses.replace(unc, not_determined=flags), intervals
