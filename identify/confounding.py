"""Whether a fitted parameter is confounded with what calibration fitted.

A calibrated spec (``dtwin calibrate``, :mod:`dtwin.identify.calibrate`) carries quantities
fitted from healthy records with the mesh stiffnesses, damping and inertias held at the spec's
values, two of them in metres:

- the mesh excitation, transmission-error harmonics
  (:class:`dtwin.model.parts.mesh_excitation.MeshExcitation`). Below the mesh modes the dynamic mesh
  force a transmission error ``e`` drives is close to ``k e`` (``k`` the mesh stiffness in
  series with the bodies' compliance);
- the load shares (``imperfections.load_sharing``), which the twin gets as mesh clearances
  solved at the spec's stiffness (:func:`dtwin.model.parts.imperfections.load_share_offsets`); a
  clearance unloads its planet by the stiffness times it.

What a record of a few kHz measures is those products. A later fit that frees a stiffness
with the calibration held reads the products as the stiffness: it finds a value, with an
interval that only says how well the products are known. Had calibration been run at that
stiffness, the excitation and clearances would have come out different and the fit would have
found no reason to move. The record cannot tell the stiffness from them; the interval claims
it can.

**The check** (:func:`calibration_confounding`). At the optimum the free parameters are joined
by the calibrated quantities: the excitation harmonics (``excitation_<mesh>_<cos|sin>_<h>``,
those the spec carries nonzero) and the clearances of planets 1 … N-1 (``mesh_clearance_i``, m;
a common clearance moves no share; not registry names, as the spec states shares, not
clearances). The Jacobian is taken again and the same analysis
(:func:`dtwin.identify.uncertainty.analyse`: sandwich covariance, lack-of-fit widening, the
half-width and near-null rules) is repeated with them free, without a prior (calibration
fitted them at the spec's stiffness, so its intervals do not hold at another). A parameter
determined with the calibration held and not with it free is flagged NOT DETERMINED, and the
flag gives its interval with the calibration free. A parameter fitted beside them keeps the
interval and status it has with the calibration held unless the check flags it.

The check runs when the spec is calibrated and a free parameter is one that calibration held
at the spec's value: the mesh and support stiffnesses, damping ratios, masses and inertias, and
a transmission-error amplitude on top of the calibrated one (registry sections ``mesh``,
``supports``, ``damping``, ``lumped``). It costs one forward-mode Jacobian with a column per
free parameter, per calibrated harmonic and per clearance. It does not run for a fit of tooth
faults alone, although the excitation moves a severity too: with the excitation free, a
fault's sidebands stand against mesh lines whose level the excitation sets, and the interval
widens (by how much: benchmarks/README.md, "Moved from module docstrings (#52)"). The severity's own rules — the lack-of-fit widening, the band
jackknife, the loss shapes (:mod:`dtwin.identify.severity`) — are what its intervals carry.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from dtwin.model.parts.imperfections import MeshOffsets
from dtwin.model.registry import N_EXCITATION_HARMONICS, lookup
from dtwin.spec.build import is_calibrated

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
    if not is_calibrated(spec):
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
    return lookup(name).section in CONFOUNDABLE_SECTIONS and not name.startswith("excitation_")


def _has_shares(spec) -> bool:
    return is_calibrated(spec) and spec["imperfections"]["load_sharing"] is not None


def needs_check(free, spec) -> bool:
    """Whether :func:`calibration_confounding` applies: `spec` is calibrated, carries an
    excitation or load shares, and one of the `free` names is a parameter calibration held
    fixed."""
    return ((bool(calibrated_excitation(spec)) or _has_shares(spec))
            and any(_confoundable(n) for n in free))


@eqx.filter_jit
def _clearance_jacobian(problem, i: int):
    """The residuals' forward-mode Jacobian at θ = 0 in the clearances of planets 1 … N-1 (m,
    both meshes of a planet), those of the `MeshOffsets` part ``problem.twin.parts[i]``."""
    part = problem.twin.parts[i]
    theta = jnp.zeros(problem.pset.size)

    def residuals(d):
        moved = MeshOffsets(part.e_sp.at[1:].add(d), part.e_rp.at[1:].add(d))
        return eqx.tree_at(lambda q: q.twin.parts[i], problem, moved).residuals(theta)

    return jax.jacfwd(residuals)(jnp.zeros(part.e_sp.shape[0] - 1))


def _clearance_columns(problem, spec):
    """``(e0, J)``: the load-share clearances of planets 1 … N-1 (planet 0 held: a common
    clearance moves no share) and :func:`_clearance_jacobian`, or None when the twin carries
    no calibrated shares."""
    twin = problem.twin
    i = next((k for k, p in enumerate(twin.parts) if isinstance(p, MeshOffsets)), None)
    if i is None or not _has_shares(spec) or twin.n_planets < 2:
        return None
    return np.asarray(twin.parts[i].e_sp[1:]), np.asarray(_clearance_jacobian(problem, i))


def calibration_confounding(problem, theta, unc: Uncertainty, spec, *, groups, expected_rss,
                            jacobian) -> tuple[Uncertainty, dict[str, tuple[float, float]]]:
    """`unc` with the parameters that the calibrated excitation and load-share clearances
    confound flagged (module docstring).

    **Arguments:** `problem` (:class:`dtwin.identify.problem.Problem`) and its optimum `theta`;
    `unc`: the analysis with the calibration held; `spec`: the calibrated spec; `groups`,
    `expected_rss`: as for :func:`dtwin.identify.uncertainty.analyse`; `jacobian(theta,
    problem) -> (r, J)`: the residuals and forward-mode Jacobian of a problem.

    **Returns:** ``(unc, intervals)``: the analysis with the new flags added to
    ``not_determined``, and the 95 % interval (SI) of every free parameter with the
    calibration's quantities free.
    """
    pset = problem.pset
    nuisance = [n for n in calibrated_excitation(spec) if n not in pset.free]
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
                         periodic=problem.periodic, periodic_settle=problem.periodic_settle)
    r, J = jacobian(jnp.zeros(joint.size), prob)
    r, J = np.asarray(r), np.asarray(J)
    what = [f"{len(nuisance) // 2} transmission-error harmonics"] if nuisance else []
    clear = _clearance_columns(prob, spec)
    if clear is not None:
        # the clearances as parameters of their own (θ unit 1 m, "none" transform), appended
        e0, Jc = clear
        k = e0.shape[0]
        joint = ParameterSet(
            free=joint.free + tuple(f"mesh_clearance_{i}" for i in range(1, k + 1)),
            transforms=joint.transforms + ("none",) * k,
            x0=jnp.concatenate([joint.x0, jnp.asarray(e0)]),
            lower=joint.lower + (-np.inf,) * k, upper=joint.upper + (np.inf,) * k,
            fixed=joint.fixed, priors=joint.priors)
        J = np.concatenate([J, Jc], axis=1)
        what.append(f"{k} load-share clearances")
    if joint.size == pset.size:
        return unc, {}
    wide = analyse(joint, np.zeros(joint.size), r, J, groups,
                   n_profiled_gains=problem.n_profiled_gains, expected_rss=expected_rss)
    intervals = {n: (float(wide.interval[i, 0]), float(wide.interval[i, 1]))
                 for i, n in enumerate(pset.free)}
    flags = dict(unc.not_determined)
    for n in pset.free:
        if n in flags or n not in wide.not_determined:
            continue
        lo, hi = intervals[n]
        flags[n] = (f"confounded with the calibration ({' and '.join(what)}, fitted at the "
                    f"spec's values): with them free, {wide.not_determined[n]}; 95 % interval "
                    f"[{lo:.4g}, {hi:.4g}]")
    return dataclasses.replace(unc, not_determined=flags), intervals
