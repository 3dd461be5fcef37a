"""Fit the twin's parameters to measured records: optimistix least squares through diffrax.

:func:`fit` runs, in order, before any simulation: the parameter names against the registry
(:class:`dtwin.identify.params.ParameterSet`), the records (NaN, rate, length:
:func:`dtwin.identify.residuals.observe`), the operating point of each record
(:mod:`dtwin.identify.operating_point`), all in :func:`dtwin.identify.problem.make_problem`.
Then

1. **multi-start**: a coarse grid of starts in the nondimensional θ (every combination of
   ``{-spread, 0, +spread}`` per parameter, sub-sampled with `seed` to `n_starts`, always with
   θ = 0, the initial values: :func:`start_grid`) is evaluated in **one** batched call
   (``jax.vmap`` on a GPU, ``jax.lax.map`` on a CPU: :func:`dtwin.identify.solve.batch_mode`);
   the `refine` best go on;
2. **refinement**: ``optimistix.least_squares`` (Levenberg–Marquardt by default, Gauss–Newton or
   Dogleg) from those starts, again in one batched call (one start: not batched;
   :func:`dtwin.identify.solve.refine_starts`); Jacobians in forward mode through diffrax
   (``SolverOptions(adjoint="forward")``, ``options=dict(jac="fwd")``; residuals and Jacobian
   from one primal-and-tangents solve per LM step; only the parameters that change the twin
   ride through the ODE, :func:`dtwin.identify.solve.value_and_jacfwd`; its cost against one
   simulation: benchmarks/README.md, "Fit") — or reverse mode (``jac="rev"``: checkpointed
   adjoint, for many parameters); it stops on a Cauchy test or when the optimum is within
   `sigma_tol` standard errors (:func:`dtwin.identify.stopping.make_solver`);
3. the best converged start is the answer; :mod:`dtwin.identify.uncertainty` adds intervals,
   correlations and identifiability flags from the residuals and Jacobian of the solver's last
   accepted step there (no further simulation); a severity's profile or a stiffness's scan
   that passes a point of lower loss is refined from (:data:`MAX_RELOCATIONS`); the values are
   checked against the spec (:mod:`dtwin.identify.spec_checks`).

Several records are fitted jointly by concatenating their residual vectors (steady records at
several speeds, run-ups). Failures are reported in :class:`FitResult` (``converged``,
``at_bound``, ``message``); with ``throw=True`` a :class:`~dtwin.errors.FitError` is raised.

:func:`fit` fits one problem (:func:`fit_one`), or hands a calibrated spec's fault severity to
:func:`dtwin.identify.excitation_response.fit_both_ends`, which fits it with both ends of the
calibration's excitation/response split (`FitSettings.splits`).

The names of the rooms :func:`fit` uses stay importable from here: :class:`Problem`,
:func:`make_problem`, :func:`check_free` (:mod:`dtwin.identify.problem`), :class:`FitResult`
(:mod:`dtwin.identify.fit_result`), :func:`fit_batch`, :func:`stack_problems`
(:mod:`dtwin.identify.fit_batch`), :func:`batch_mode` (:mod:`dtwin.identify.solve`),
:data:`SOLVERS`, :data:`SIGMA_TOL` (:mod:`dtwin.identify.stopping`).
"""

from __future__ import annotations

import dataclasses
import itertools
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

import jax.numpy as jnp
import numpy as np

from dtwin import _heap
from dtwin.errors import FitError
from dtwin.model.registry import REGISTRY

from .excitation_response import fit_both_ends, other_split
from .fit_batch import fit_batch, stack_problems
from .fit_result import FitResult
from .fit_settings import FitSettings, settings_and_problem_kwargs
from .params import ParameterSet
from .problem import PROBLEM_KEYS, Problem, check_free, make_problem
from .residuals import point_groups, window_reach
from .solve import (
    batch_mode,
    batched_loss,
    batched_residuals,
    best_start,
    refine_starts,
    settled_fit,
)
from .spec_checks import checked_against_spec
from .stopping import SIGMA_TOL, SOLVERS
from .uncertainty import Uncertainty, analyse, expected_noise_rss

__all__ = ["FitResult", "FitSettings", "Problem", "SIGMA_TOL", "SOLVERS", "batch_mode",
           "check_free", "fit", "fit_batch", "fit_one", "make_problem", "stack_problems",
           "start_grid"]

#: How many times :func:`fit` goes on from a point of lower loss that a severity's profile or a
#: stiffness's scan passed (:class:`dtwin.identify.uncertainty.Uncertainty` ``better``).
MAX_RELOCATIONS = 2
#: Registry sections whose ``log`` parameters (stiffnesses, masses, inertias) :func:`fit` scans
#: over a decade each side of the optimum (:mod:`dtwin.identify.uncertainty`, "Scan").
SCANNED_SECTIONS = ("mesh", "supports", "lumped")


def fit(records, spec_or_twin, free: Sequence[str] | str | ParameterSet,
        settings: FitSettings | None = None, *, problem: Problem | None = None,
        **overrides: Any) -> FitResult:
    """Fit the free parameters of a twin to one or several records.

    **Arguments:**

    - `records`: a `dtwin.io.Record` or a list (fitted jointly).
    - `spec_or_twin`: a spec (path, mapping, `Spec`; built with ``kind``: default the kind a
      calibrated spec was calibrated with, otherwise torsional, :func:`dtwin.spec.build.twin_kind`)
      or a `Twin`.
    - `free`: registry names (list or ``"a,b,c"``) or a `ParameterSet`.
    - `settings`: how the fit runs, a :class:`~dtwin.identify.fit_settings.FitSettings`
      (None: its defaults): solver, starts, refine, spread, seed, jac, max_steps, tol,
      sigma_tol, batch, uncertainty, scan, confounding, progress, throw, splits (each
      documented there).
    - `problem`: a prepared :class:`Problem` to fit instead of one made from the records (no
      excitation/response split then).
    - `overrides`: keyword arguments named like a `FitSettings` field replace it
      (``fit(rec, spec, "sun_fault", max_steps=3)``); those of :func:`make_problem` (``f_sun``,
      ``runup``, ``features``, ``weights``, ``initial``, ``fixed``, ``bounds``, ``priors``,
      ``channel``, ``discard``, ``oversample``, ``kind``, ``rtol``, ``atol``, ``periodic``)
      shape the problem; any other name is a `SettingsError` listing both.

    **Returns:** :class:`FitResult`.
    """
    settings, problem_kwargs = settings_and_problem_kwargs(settings, overrides, PROBLEM_KEYS)
    names = None if problem is not None or isinstance(free, ParameterSet) else check_free(free)
    other = None if names is None else other_split(spec_or_twin, names, settings.splits)
    if other is not None:  # both ends of the calibration's split (dtwin.identify.excitation_response)
        return fit_both_ends(fit_one, records, (spec_or_twin, other), free, names, settings,
                             problem_kwargs)
    return fit_one(records, spec_or_twin, free, settings, problem=problem, **problem_kwargs)


@dataclasses.dataclass
class _Runs:
    """The refined starts, one row each: θ, converged, steps, loss, residuals, Jacobian, loss
    history and its length (:func:`dtwin.identify.solve.outcome`, as numpy)."""

    th: np.ndarray
    ok: np.ndarray
    steps: np.ndarray
    fl: np.ndarray
    rs: np.ndarray
    Js: np.ndarray
    hist: np.ndarray
    n_hist: np.ndarray

    @classmethod
    def of(cls, out) -> _Runs:
        return cls(*(np.asarray(a) for a in out[:8]))

    def rows(self, pset: ParameterSet, **extra) -> list[dict[str, Any]]:
        return [{"theta": self.th[i].tolist(), "converged": bool(self.ok[i]),
                 "steps": int(self.steps[i]), "loss": float(self.fl[i]),
                 "values": pset.as_dict(self.th[i]), **extra} for i in range(self.th.shape[0])]

    def then(self, other: _Runs) -> _Runs:
        return _Runs(*(np.concatenate([a, b]) for a, b in
                       zip(dataclasses.astuple(self), dataclasses.astuple(other), strict=True)))


def fit_one(records, spec_or_twin, free: Sequence[str] | str | ParameterSet,
            settings: FitSettings, *, problem: Problem | None = None,
            **problem_kwargs: Any) -> FitResult:
    """:func:`fit` of one problem (no excitation/response split): starts, refinement,
    uncertainty with relocations, checks against the spec, the result."""
    s = settings
    mode = batch_mode(s.batch)
    t0 = time.perf_counter()
    if problem is None:
        problem, ops = make_problem(records, spec_or_twin, free, jac=s.jac, **problem_kwargs)
    else:
        ops = []
    pset = problem.pset

    def say(m):
        if s.progress:
            print(f"[{time.perf_counter() - t0:7.1f} s] {m}", file=sys.stderr, flush=True)

    say(pset.summary())
    thetas = jnp.asarray(_start_thetas(pset, s))
    losses, chosen = _evaluate_starts(thetas, problem, s.refine, mode, say)
    _heap.before_first_fit()
    problem, out, settle_notes = settled_fit(
        problem, lambda prob, th: refine_starts(th, prob, s.solver, s.tol, s.tol, s.jac,
                                                s.max_steps, s.sigma_tol, mode), chosen,
        lambda out: np.asarray(out[-1])[best_start(np.asarray(out[3]))], say)
    runs = _Runs.of(out)
    refined = runs.rows(pset)
    best = best_start(runs.fl)
    say(f"refined losses: {np.array2string(runs.fl, precision=5)}; best {runs.fl[best]:.6g} "
        f"after {int(runs.steps[best])} steps")
    unc, relocated = None, []
    if s.uncertainty:
        unc, runs, best = _analyse_and_relocate(problem, runs, best, refined, relocated, s, mode,
                                                say)
        unc = checked_against_spec(unc, problem, runs.th[best], spec_or_twin,
                                   confounding=s.confounding,
                                   groups=point_groups(problem.observations),
                                   expected_rss=expected_noise_rss(problem.observations), say=say)
    res = _result(problem, runs, best, unc, s, thetas, losses, refined, relocated, settle_notes,
                  ops, t0)
    say(res.table())
    if s.throw and (not res.converged or res.at_bound):
        raise FitError(res.message)
    return res


def start_grid(p: int, n_starts: int, spread: float, seed: int) -> np.ndarray:
    """θ starts: 0 first, then the corners and edges of ``{-spread, 0, spread}^p`` sub-sampled."""
    pts = np.array(list(itertools.product((-spread, 0.0, spread), repeat=p)), dtype=float)
    pts = pts[np.any(pts != 0, axis=1)]
    rng = np.random.default_rng(seed)
    rng.shuffle(pts)
    return np.concatenate([np.zeros((1, p)), pts[: max(n_starts - 1, 0)]])


def _start_thetas(pset: ParameterSet, s: FitSettings) -> np.ndarray:
    """The θ starts of `s.starts`: a grid of that many, the physical values of dicts, or θ."""
    starts = s.starts
    if isinstance(starts, (int, np.integer)):
        return start_grid(pset.size, int(starts), s.spread, s.seed)
    if len(starts) and isinstance(starts[0], Mapping):
        return np.stack([pset.theta(v) for v in starts])
    return np.atleast_2d(np.asarray(starts, dtype=float))


def _evaluate_starts(thetas, problem: Problem, refine: int, mode: str, say):
    """``(losses, chosen)``: the loss of each start (one batched call; NaN for a single start,
    whose loss is the first of the solver's history) and the `refine` best starts."""
    if thetas.shape[0] > 1:
        say(f"evaluating {thetas.shape[0]} starts in one batch …")
        losses = np.asarray(batched_loss(thetas, problem, mode))
        order = np.argsort(np.where(np.isfinite(losses), losses, np.inf))
    else:
        losses, order = np.asarray([np.nan]), np.arange(1)
    chosen = thetas[np.asarray(order[: max(1, refine)])]
    if thetas.shape[0] > 1:
        say(f"start losses: {np.array2string(losses, precision=4)}; refining {chosen.shape[0]}")
    else:
        say("one start: refining it (its loss is the first of the history)")
    return losses, chosen


def _analyse_and_relocate(problem: Problem, runs: _Runs, best: int, refined: list,
                          relocated: list, s: FitSettings, mode: str, say
                          ) -> tuple[Uncertainty, _Runs, int]:
    """``(uncertainty, runs, best)``: the uncertainty at the best start's optimum, from the
    residuals and Jacobian of the solver's last accepted step; where a severity's profile or a
    stiffness's scan passed a point of lower loss (the optimum was a local one) the solver goes
    on from that point (the same compiled refinement, up to :data:`MAX_RELOCATIONS` times),
    appending to `refined` and `relocated`."""
    pset = problem.pset
    groups = point_groups(problem.observations)
    expected = expected_noise_rss(problem.observations)
    while True:
        unc = analyse(pset, runs.th[best], runs.rs[best], runs.Js[best], groups,
                      n_profiled_gains=problem.n_profiled_gains,
                      profile_fn=lambda ts: batched_residuals(jnp.asarray(ts), problem, mode),
                      expected_rss=expected, scan=_scanned(pset) if s.scan else (),
                      reach=window_reach(problem.observations))
        if unc.better is None or len(relocated) >= MAX_RELOCATIONS:
            return unc, runs, best
        name, th_b, _ = unc.better
        say(f"the profile or scan of {name} passed a point of lower loss ({name} = "
            f"{pset.as_dict(th_b)[name]:.4g}): refining from it")
        new = _Runs.of(refine_starts(jnp.asarray(th_b)[None, :], problem, s.solver, s.tol, s.tol,
                                     s.jac, s.max_steps, s.sigma_tol, mode))
        refined.extend(new.rows(pset, from_profile_of=name))
        if not new.fl[0] < runs.fl[best]:
            return unc, runs, best
        relocated.append((name, float(runs.fl[best]), float(new.fl[0]),
                          "scan" if name in unc.scanned else "profile"))
        runs = runs.then(new)
        best = runs.th.shape[0] - 1
        say(f"refined from that point: loss {runs.fl[best]:.6g} after "
            f"{int(runs.steps[best])} steps")


def _result(problem: Problem, runs: _Runs, best: int, unc, s: FitSettings, thetas, losses,
            refined, relocated, settle_notes, ops, t0) -> FitResult:
    """The :class:`FitResult` of the best run, with its convergence message."""
    pset = problem.pset
    theta = runs.th[best]
    steps = int(runs.steps[best])
    at_bound = pset.at_bound(theta)
    hit_limit = steps >= s.max_steps
    converged = bool(runs.ok[best]) and not hit_limit
    history = [float(v) for v in np.asarray(runs.hist[best])[: int(runs.n_hist[best])]]
    if thetas.shape[0] == 1 and history:  # the loss at the one start: the solver's first call
        losses = np.asarray([history[0]])
    msgs = []
    if hit_limit:
        msgs.append(f"stopped at the step limit ({steps} of max_steps={s.max_steps}) "
                    "before the stopping rule was met; raise max_steps (--max-steps), use more "
                    "starts, or free fewer parameters")
    elif not converged:
        msgs.append(f"not converged after {steps} steps (max_steps={s.max_steps}); "
                    "raise max_steps, use more starts, or free fewer parameters")
    if at_bound:
        msgs.append(f"parameters at a bound: {', '.join(at_bound)} (the data push them out of "
                    "their range: check the spec, the bounds or the model)")
    message = "; ".join((msgs or ["converged"]) + settle_notes)
    return FitResult(
        names=pset.free, values=pset.as_dict(theta), theta=theta,
        initial=pset.as_dict(np.zeros(pset.size)), uncertainty=unc, loss=float(runs.fl[best]),
        loss_history=history or [float(runs.fl[best])],
        start_losses=losses, starts=np.asarray(thetas), refined=refined, converged=converged,
        at_bound=at_bound, message=message, iterations=steps,
        wall_time=time.perf_counter() - t0, operating_points=ops, problem=problem,
        residuals=np.asarray(runs.rs[best]), jacobian=np.asarray(runs.Js[best]),
        relocations=[{"profile_of": n, "loss_before": a, "loss_after": b, "by": by}
                     for n, a, b, by in relocated],
    )


def _scanned(pset: ParameterSet) -> tuple[str, ...]:
    """The free ``log`` parameters of `pset` in :data:`SCANNED_SECTIONS`."""
    return tuple(n for n, tr in zip(pset.free, pset.transforms, strict=True)
                 if tr == "log" and n in REGISTRY and REGISTRY[n].section in SCANNED_SECTIONS)

