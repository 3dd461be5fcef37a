"""Fit many records of one gearbox type in one compiled call (:func:`fit_batch`): the
records' problems stacked along a leading axis (:func:`stack_problems`) and refined together
(``vmap`` on a GPU, ``jax.lax.map`` on a CPU), one start each."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from dtwin import _heap
from dtwin.errors import FitError

from .excitation_response import fit_batch_both_ends, other_split
from .fit_result import FitResult
from .fit_settings import FitSettings, settings_and_problem_kwargs
from .problem import PROBLEM_KEYS, Problem, check_free, make_problem
from .residuals import point_groups, window_reach
from .solve import batch_mode, least_squares, over_batch, residual_fn, settled_fit
from .spec_checks import checked_against_spec
from .stopping import make_solver
from .uncertainty import analyse, expected_noise_rss

__all__ = ["fit_batch", "stack_problems"]

#: FitSettings fields :func:`fit_batch` has no use for (one start per record, no profile or
#: scan, no progress, no throw): naming one is an error.
UNUSED = ("starts", "refine", "spread", "seed", "scan", "progress", "throw")


def stack_problems(problems: Sequence[Problem]) -> Problem:
    """Stack problems of one structure (same record length, rate, rounded speed, free names)
    along a leading axis of every array, for ``vmap`` over records.

    **Raises:** `FitError` when the structures differ (group records by length, rate and speed,
    or use ``Features(grid="orders")`` with a common ``order_step``)."""
    statics = [eqx.partition(p, eqx.is_array)[1] for p in problems]
    shapes = [jax.tree.map(lambda a: a.shape, eqx.filter(p, eqx.is_array)) for p in problems]
    if any(s != statics[0] for s in statics[1:]) or any(s != shapes[0] for s in shapes[1:]):
        raise FitError("records of one batch must share length, rate, speed (to 0.1 Hz) and "
                       "settings; group them, or fit them one by one")
    arrays = [eqx.filter(p, eqx.is_array) for p in problems]
    stacked = jax.tree.map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *arrays)
    return eqx.combine(stacked, statics[0])


@eqx.filter_jit
def refine_records(thetas, stacked: Problem, solver_name: str, rtol: float, atol: float,
                    jac: str, max_steps: int, sigma_tol: float = 0.0, batch: str = "vmap"):
    solver = make_solver(solver_name, rtol, atol, sigma_tol, history=max_steps + 1)
    arrays, static = eqx.partition(stacked, eqx.is_array)

    def one(theta0, arr):
        prob = eqx.combine(arr, static)
        return least_squares(residual_fn(jac), solver, theta0, prob, jac, max_steps)

    return over_batch(one, batch, thetas, arrays)


def fit_batch(records: Sequence, spec_or_twin, free: Sequence[str] | str,
              settings: FitSettings | None = None, **overrides: Any) -> list[FitResult]:
    """Fit many records of one gearbox type in one compiled call (one start each, θ = 0):
    ``vmap`` over the records on a GPU, ``jax.lax.map`` on a CPU (`batch`,
    :func:`dtwin.identify.solve.batch_mode`). Records must share length, rate and speed to
    0.1 Hz (:func:`stack_problems`); per-record keyword lists (``f_sun``…) are not taken here:
    pass scalars. `settings` and `overrides` as :func:`dtwin.identify.fit.fit` (solver, jac,
    max_steps, tol, sigma_tol, batch, uncertainty, confounding, splits; the start grid, scan,
    progress and throw do not apply: naming them is a `SettingsError`). Uncertainties come
    from the residuals and Jacobian of each record's last accepted LM step, checked against a
    spec's calibration as in :func:`~dtwin.identify.fit.fit` (`confounding`); no severity is
    profiled and no stiffness scanned (:func:`~dtwin.identify.fit.fit` does both). `splits`: as
    for :func:`~dtwin.identify.fit.fit` (both ends of a calibrated spec's excitation/response
    split, a batch each, chosen per record:
    :func:`dtwin.identify.excitation_response.fit_batch_both_ends`).
    **Returns:** one :class:`FitResult` per record, as :func:`~dtwin.identify.fit.fit` would."""
    s, problem_kwargs = settings_and_problem_kwargs(settings, overrides, PROBLEM_KEYS,
                                                    unused=UNUSED)
    names = check_free(free)
    other = other_split(spec_or_twin, names, s.splits)
    if other is not None:  # both ends of the calibration's split
        return fit_batch_both_ends(fit_batch, records, (spec_or_twin, other), free, names, s,
                                   problem_kwargs)
    t0 = time.perf_counter()
    made = [make_problem(r, spec_or_twin, free, jac=s.jac, **problem_kwargs) for r in records]
    problems = [m[0] for m in made]
    _heap.before_first_fit()

    def refine(settled: Problem, starts):
        # one structure: the records share length, rate, speed and so the settling time
        stacked = stack_problems([_settled_like(pr, settled) for pr in problems])
        return refine_records(starts, stacked, s.solver, s.tol, s.tol, s.jac, s.max_steps,
                              s.sigma_tol, batch_mode(s.batch))

    settled, out, settle_notes = settled_fit(
        problems[0], refine, jnp.zeros((len(problems), problems[0].pset.size)),
        lambda out: max((d for d in np.asarray(out[-1]) if np.isfinite(d)), default=0.0),
        lambda m: None)
    problems = [_settled_like(pr, settled) for pr in problems]
    wall = time.perf_counter() - t0
    return [_record_result(i, prob, out, made[i][1], s, spec_or_twin, settle_notes, wall)
            for i, prob in enumerate(problems)]


def _settled_like(problem: Problem, settled: Problem) -> Problem:
    """`problem` with the periodicity settings of `settled`."""
    return dataclasses.replace(problem, periodic=settled.periodic,
                               periodic_settle=settled.periodic_settle)


def _record_result(i: int, prob: Problem, out, ops, s: FitSettings, spec_or_twin,
                   settle_notes: list[str], wall: float) -> FitResult:
    """The :class:`FitResult` of record `i` of a batch's outcome `out`."""
    th, ok, steps, fl, rs, Js, hist, n_hist, _ = out
    th, ok, steps, fl = (np.asarray(th), np.asarray(ok), np.asarray(steps), np.asarray(fl))
    pset = prob.pset
    p = pset.size
    unc = None
    if s.uncertainty:
        unc = analyse(pset, th[i], np.asarray(rs[i]), np.asarray(Js[i]),
                      point_groups(prob.observations),
                      n_profiled_gains=prob.n_profiled_gains,
                      expected_rss=expected_noise_rss(prob.observations),
                      reach=window_reach(prob.observations))
        unc = checked_against_spec(unc, prob, th[i], spec_or_twin, confounding=s.confounding,
                                   groups=point_groups(prob.observations),
                                   expected_rss=expected_noise_rss(prob.observations))
    n_steps = int(steps[i])
    return FitResult(
        names=pset.free, values=pset.as_dict(th[i]), theta=th[i],
        initial=pset.as_dict(np.zeros(p)), uncertainty=unc, loss=float(fl[i]),
        loss_history=[float(v) for v in np.asarray(hist[i])[: int(n_hist[i])]] or [float(fl[i])],
        start_losses=np.zeros(0),  # no start evaluated alone
        starts=np.zeros((1, p)), refined=[],
        converged=bool(ok[i]) and n_steps < s.max_steps, at_bound=pset.at_bound(th[i]),
        message="; ".join([
            "converged" if ok[i] and n_steps < s.max_steps else
            f"stopped at the step limit ({n_steps} of max_steps={s.max_steps})"
            if n_steps >= s.max_steps else
            f"not converged after {n_steps} steps"] + settle_notes),
        iterations=n_steps, wall_time=wall, operating_points=ops, problem=prob,
        residuals=np.asarray(rs[i]), jacobian=np.asarray(Js[i]),
    )
