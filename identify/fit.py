"""Fit the twin's parameters to measured records: optimistix least squares through diffrax.

:func:`fit` runs, in order, before any simulation: the parameter names against the registry
(:class:`dtwin.identify.params.ParameterSet`), the records (NaN, rate, length:
:func:`dtwin.identify.residuals.observe`), the operating point of each record
(:mod:`dtwin.identify.operating_point`). Then

1. **multi-start**: a coarse grid of starts in the nondimensional θ (every combination of
   ``{-spread, 0, +spread}`` per parameter, sub-sampled with `seed` to `n_starts`, always with
   θ = 0, the initial values) is evaluated in **one** batched call (``jax.vmap`` on a GPU,
   ``jax.lax.map`` on a CPU: :func:`batch_mode`); the `refine` best go on;
2. **refinement**: ``optimistix.least_squares`` (Levenberg–Marquardt by default, Gauss–Newton or
   Dogleg) from those starts, again in one batched call (one start: not batched);
   Jacobians in forward mode
   through diffrax (``SolverOptions(adjoint="forward")``, ``options=dict(jac="fwd")``; residuals
   and Jacobian from one primal-and-tangents solve per LM step, :func:`_residuals_fwd`; only
   the parameters that change the twin ride through the ODE, :func:`_value_and_jacfwd`; its
   cost against one simulation: benchmarks/README.md, "Fit") — or reverse mode (``jac="rev"``:
   checkpointed adjoint, for many parameters); it stops on a Cauchy test or when the optimum
   is within `sigma_tol` standard errors (:func:`_make_solver`);
3. the best converged start is the answer; :mod:`dtwin.identify.uncertainty` adds intervals,
   correlations and identifiability flags from the residuals and Jacobian of the solver's last
   accepted step there (no further simulation).

Several records are fitted jointly by concatenating their residual vectors (steady records at
several speeds, run-ups). Failures are reported in :class:`FitResult` (``converged``,
``at_bound``, ``message``); with ``throw=True`` a :class:`~dtwin.errors.FitError` is raised.
"""

from __future__ import annotations

import dataclasses
import itertools
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from dtwin import _heap
from dtwin.build import build_twin, is_calibrated, twin_kind
from dtwin.errors import DtwinError, FitError, ParameterError, RecordError, SettingsError
from dtwin.registry import REGISTRY, lookup
from dtwin.simulate import SolverOptions, settling_sequence
from dtwin.spec import Spec, load_spec
from dtwin.twin import Twin

from .confounding import calibrated_excitation, calibration_confounding, needs_check
from .low_band import LOW_BAND_LOCATIONS, with_low_band_problem
from .operating_point import estimate_speed_profile, nominal_speed, resolve_speed
from .params import ParameterSet
from .plausibility import MESHES, flag_implausible
from .residuals import (
    FAILED_RESIDUAL,
    Features,
    Observation,
    _check,
    fitted_levels,
    levels_from_residuals,
    model_signal_and_defect,
    observation_residuals,
    observe,
    point_groups,
    residual_count,
    window_reach,
)
from .split import (
    SPLIT_CALIBRATED,
    SPLIT_STIFFNESS,
    choose_split,
    other_split,
)
from .uncertainty import MODEL_FORM_REASON, Uncertainty, analyse, expected_noise_rss

__all__ = ["FitResult", "Problem", "SOLVERS", "fit", "fit_batch", "make_problem", "stack_problems"]

SOLVERS = ("lm", "gauss-newton", "dogleg")
#: Fault severities whose split is scored with the low band too: those of
#: :data:`dtwin.identify.low_band.LOW_BAND_LOCATIONS` (the sun's and the ring's comb lies where
#: the records put it).
LOW_BAND_FAULTS = tuple(f"{loc}_fault" for loc in LOW_BAND_LOCATIONS)
#: Default statistical stopping rule: stop when the optimum is within this many standard
#: errors of the accepted point (:func:`gauss_newton_step_in_sigma`). Above the ODE solver's
#: noise floor: at rtol = 1e-4 the Gauss–Newton step at points within 0.03 in θ of the optimum
#: of the benchmark fit measures 0.03–0.13 σ (benchmarks/README.md, "Fit"); with
#: 0.05 a fit could spend 15 steps chasing that noise. A step of 0.1 σ moves no interval
#: noticeably.
SIGMA_TOL = 0.1
#: How many times :func:`fit` goes on from a point of lower loss that a severity's profile or a
#: stiffness's scan passed (:class:`dtwin.identify.uncertainty.Uncertainty` ``better``).
MAX_RELOCATIONS = 2
#: Registry sections whose ``log`` parameters (stiffnesses, masses, inertias) :func:`fit` scans
#: over a decade each side of the optimum (:mod:`dtwin.identify.uncertainty`, "Scan").
SCANNED_SECTIONS = ("mesh", "supports", "lumped")


class Problem(eqx.Module):
    """A fitting problem: the prepared twin, the parameter set and the observations.

    A pytree: arrays (twin parameters, measured levels) are leaves, shapes and settings are
    static, so one compiled residual serves every problem of the same structure (other records
    of the same length, other noise, other starting values).
    """

    twin: Any
    pset: ParameterSet
    observations: tuple[Observation, ...]
    rtol: float = eqx.field(static=True, default=1e-5)
    atol: float = eqx.field(static=True, default=1e-5)
    adjoint: str = eqx.field(static=True, default="forward")
    periodic: str = eqx.field(static=True, default="off")
    periodic_settle: float = eqx.field(static=True, default=0.1)

    def solver_options(self):
        return SolverOptions(rtol=self.rtol, atol=self.atol, adjoint=self.adjoint,
                             periodic=self.periodic, periodic_settle=self.periodic_settle)

    def signals(self, theta):
        """``(signals, values)``: the twin's signal per record and the parameter values (SI)
        at the unconstrained `theta`."""
        sigs, values, _ = self.simulated(theta)
        return sigs, values

    def simulated(self, theta):
        """``(signals, values, defect)``: :meth:`signals` and the largest periodicity defect
        of the records simulated over one period of the gear set and tiled (relative rms
        difference of a signal as integrated and as tiled over a probe window,
        `dtwin.simulate.SimResult.periodic_defect`; 0 where no record is tiled). A defect above `SolverOptions.periodic_tolerance` means the start-up
        transient had not died out within the settling time (:func:`fit` then fits again)."""
        values = self.pset.values(theta)
        tw = self.pset.apply(self.twin, values)
        out = [model_signal_and_defect(tw, o, self.solver_options()) for o in self.observations]
        defects = [d for _, d in out if d is not None]
        worst = jnp.max(jnp.stack(defects)) if defects else jnp.zeros(())
        return [sig for sig, _ in out], values, worst

    def residuals(self, theta):
        """The residual vector (all records, then priors) at the unconstrained `theta`."""
        return self.residuals_from(self.signals(theta)[0], theta)

    def residuals_and_defect(self, theta):
        """``(residuals, defect)`` at `theta`: :meth:`residuals` and the periodicity defect of
        :meth:`simulated`, from one simulation."""
        sigs, _, defect = self.simulated(theta)
        return self.residuals_from(sigs, theta), defect

    def residuals_from(self, sigs, theta):
        """The residual vector from simulated signals `sigs` (one per record) at `theta`:
        everything after the ODE solve (sensor gain, spectra, priors)."""
        values = self.pset.values(theta)
        gain = self.pset.gain(values)
        rs = [observation_residuals(s, o, gain) for s, o in zip(sigs, self.observations, strict=True)]
        rs.append(self.pset.prior_residuals(values))
        r = jnp.concatenate(rs)
        return jnp.where(jnp.isfinite(r), r, FAILED_RESIDUAL)

    @property
    def n_profiled_gains(self) -> int:
        """Nuisance values profiled out per evaluation (degrees of freedom lost): one gain per
        record with ``gain="profile"``, one white-noise level per spectrogram record."""
        noise = sum(1 for o in self.observations if o.noise is not None)
        if "sensor_gain" in self.pset.free:
            return noise
        return noise + sum(1 for o in self.observations if o.gain_mode == "profile")


def _settled_fit(problem: Problem, refine, starts, defect_of, say
                 ) -> tuple[Problem, Any, list[str]]:
    """``(problem, outcome, notes)``: ``refine(problem, starts)``, run again with a longer
    settling time, then on the whole record, while the fitted response is not periodic; `notes`
    say why each time (for the fit's message).

    A fit simulates one period of the gear set after `Problem.periodic_settle` and tiles it
    inside its compiled solve, where the parameters are traced and nothing can be checked; the solve
    returns the periodicity defect of its last accepted point instead
    (:meth:`Problem.simulated`), and ``defect_of(outcome)`` picks the one that counts (the best
    start's, a batch's largest). Where it exceeds `SolverOptions.periodic_tolerance` (a lightly
    damped mode of the drive or the housing outlasted the settling time, and the tiles' joins
    put a broadband hump in the spectrum) the fit is run again with the next option of
    `dtwin.simulate.settling_sequence`, from where the last run ended (its start where that is
    not finite): the hump moves the optimum little, so the next run needs few steps; `say`
    reports it as it happens. `starts`: one θ per row; ``outcome[0]`` holds the refined θ."""
    options = settling_sequence(problem.solver_options())
    tol = options[0].periodic_tolerance
    starts = jnp.asarray(starts)
    out = refine(problem, starts)
    notes = []
    for nxt in options[1:]:
        defect = float(defect_of(out))
        if problem.periodic == "off" or not (np.isfinite(defect) and defect > tol):
            break
        notes.append(f"the fitted response was not periodic after {problem.periodic_settle:g} s "
                     f"(defect {defect:.2g} > {tol:g}): fitted again, " + (
                         f"settling {nxt.periodic_settle:g} s" if nxt.periodic != "off"
                         else "integrating the whole record"))
        say(notes[-1])
        problem = dataclasses.replace(problem, periodic=nxt.periodic,
                                      periodic_settle=nxt.periodic_settle)
        ended = jnp.asarray(out[0])
        starts = jnp.where(jnp.all(jnp.isfinite(ended), axis=-1, keepdims=True), ended, starts)
        out = refine(problem, starts)
    return problem, out, notes


def _best(losses) -> int:
    """Index of the least finite loss (the first when none is finite)."""
    return int(np.argmin(np.where(np.isfinite(losses), losses, np.inf)))


def _loss(theta, problem: Problem):
    r = problem.residuals(theta)
    return 0.5 * jnp.sum(r * r)


BATCH_MODES = ("auto", "vmap", "map")


def batch_mode(batch: str = "auto") -> str:
    """How a batch of fits or evaluations runs inside its one compiled call: ``"vmap"`` (the
    batch members advance together, the right choice on a GPU) or ``"map"`` (``jax.lax.map``:
    one after the other, un-batched). ``"auto"``: ``"vmap"`` on a GPU/TPU, ``"map"`` on a CPU,
    where a vmapped ODE solve costs more than the same solves in sequence: the batch runs the
    solver loop until its slowest member ends, every step as selects over the whole carry
    (measured on a 2 s record at 5 kHz: 2 vmapped residual evaluations 2.2–2.8× one, 2 mapped
    1.94×; benchmarks/README.md "Fit")."""
    if batch not in BATCH_MODES:
        raise SettingsError(f"batch must be one of {BATCH_MODES}, got {batch!r}")
    if batch == "auto":
        return "map" if jax.default_backend() == "cpu" else "vmap"
    return batch


def _over_batch(f, mode: str, *xs):
    """`f` over the leading axis of the arrays `xs`: ``jax.vmap`` or ``jax.lax.map``."""
    if mode == "vmap":
        return jax.vmap(f)(*xs)
    return jax.lax.map(lambda a: f(*a), xs)


@eqx.filter_jit
def _batched_loss(thetas, problem: Problem, batch: str = "vmap"):
    return _over_batch(lambda t: _loss(t, problem), batch, thetas)


@eqx.filter_jit
def _batched_residuals(thetas, problem: Problem, batch: str = "vmap"):
    return _over_batch(lambda t: problem.residuals(t), batch, thetas)


def _value_and_jacfwd(theta, problem: Problem):
    """``(r, ∂r/∂θ)`` from one forward-mode pass: the tangents (one per parameter, batched by
    ``jax.jacfwd``) ride along the primal simulation, and the primal comes back as `aux` rather
    than being simulated a second time.

    Only the parameters that change the twin (`ParameterSet.twin_indices`) ride through the ODE
    solve, whose cost grows with the number of tangents (about one simulation each on a CPU,
    benchmarks/README.md "Fit"); the others (``sensor_gain``) act after it. The chain rule
    joins the two: with ``S(θ_twin)`` the simulated signals and ``dS`` their Jacobian,
    ``r(θ) = post(S(θ_twin), θ)`` has ``∂r/∂θ`` = the Jacobian of
    ``post(S + dS (θ_twin − θ_twin⁰), θ)`` at θ⁰ — exact, not an approximation."""
    r, J, _ = _value_jacfwd_defect(theta, problem)
    return r, J


def _value_jacfwd_defect(theta, problem: Problem):
    """``(r, ∂r/∂θ, defect)``: :func:`_value_and_jacfwd` and the periodicity defect of the
    same simulation (:meth:`Problem.simulated`)."""
    idx = problem.pset.twin_indices
    sel = np.asarray(idx, dtype=int)
    if len(idx):
        def sim(sub):
            sigs, _, defect = problem.simulated(theta.at[sel].set(sub))
            return sigs, (sigs, defect)

        dS, (sigs, defect) = jax.jacfwd(sim, has_aux=True)(theta[sel])
    else:
        (sigs, _, defect), dS = problem.simulated(theta), None

    def post(t):
        if dS is None:
            s = sigs
        else:
            d = t[sel] - theta[sel]
            s = [x + ds @ d for x, ds in zip(sigs, dS, strict=True)]
        r = problem.residuals_from(s, t)
        return r, r

    J, r = jax.jacfwd(post, has_aux=True)(theta)
    return r, J, defect


@eqx.filter_jit
def _jacobian(theta, problem: Problem):
    return _value_and_jacfwd(theta, problem)


@eqx.filter_custom_jvp
def _residuals_fwd(theta, *, problem: Problem):
    """`Problem.residuals` whose JVP materialises the Jacobian in the forward pass.

    Why: optimistix's least squares (``jac="fwd"``) calls ``jax.linearize`` at every trial point
    and materialises that linear function in each linear solve. Linearising a ``while_loop``
    (diffrax's solve) keeps no residuals: the linear function re-runs the whole loop, primal
    included, every time it is applied (JAX's partial evaluation of ``while``), so each LM step
    cost one simulation (the linearisation) plus a primal-and-tangents solve (the
    materialisation). With this rule the forward pass computes ``r`` and ``J`` in one
    primal-and-tangents solve and the linear function is ``J @ t``: one solve per LM step.
    The values are those of ``jax.jacfwd`` (the same computation). Returns
    ``(residuals, defect)`` (:meth:`Problem.residuals_and_defect`); the defect has no
    derivative."""
    return problem.residuals_and_defect(theta)


@_residuals_fwd.def_jvp
def _residuals_fwd_jvp(primals, tangents, *, problem: Problem):
    (theta,), (t_theta,) = primals, tangents
    if t_theta is None:
        return _residuals_fwd(theta, problem=problem), None
    r, J, defect = _value_jacfwd_defect(theta, problem)
    return (r, defect), (J @ t_theta, jnp.zeros_like(defect))


def _residual_fn(jac: str):
    """The residual function handed to optimistix, returning ``(residuals, defect)`` (the
    defect as the solve's auxiliary output): `_residuals_fwd` for forward-mode Jacobians,
    `Problem.residuals_and_defect` for reverse mode."""
    if jac == "fwd":
        return lambda t, prob: _residuals_fwd(t, problem=prob)
    return lambda t, prob: prob.residuals_and_defect(t)


def gauss_newton_step_in_sigma(r, J) -> jax.Array:
    """Length of the Gauss–Newton step from a point, in standard errors: ``‖J δ‖ / s`` with
    ``δ = argmin ‖r + J δ‖`` and ``s² = ‖r‖² / (m − p)`` the residual variance.

    ``‖J δ‖²`` is twice the loss decrease the local linear model still promises, and
    ``‖J δ‖² / s² = δᵀ (s² (JᵀJ)⁻¹)⁻¹ δ`` is the squared length of the step in the metric of
    the estimate's covariance ``s² (JᵀJ)⁻¹``: a value of 0.05 means the optimum lies 0.05
    standard errors away. Directions the data do
    not determine (near-null singular directions of J) promise nothing and count for nothing,
    however long the step along them."""
    return _gauss_newton_step(r, J)[0]


def _gauss_newton_step(r, J):
    """``(‖J δ‖ / s, δ)``: see :func:`gauss_newton_step_in_sigma`.

    Solved by modified Gram–Schmidt (with re-orthogonalisation) on the column-scaled J, written
    out over the `p` columns: plain XLA operations, no LAPACK call. Inside the solver's loop
    a LAPACK call would run beside optimistix's own (lineax QR of the damped step); under
    ``vmap`` both are batched LAPACK kernels that each wait on jaxlib's intra-op thread pool,
    and on a 2-core CPU the two deadlocked (observed: `jax::ParallelBatchMap` in
    ``lapack_dgeqrf_ffi`` waiting forever). A column that is (numerically) a combination of
    the earlier ones gets no step."""
    m, p = J.shape
    s2 = jnp.sum(r * r) / max(m - p, 1)
    scale = jnp.sqrt(jnp.sum(J * J, axis=0))
    scale = jnp.where(scale > 0, scale, 1.0)
    A = J / scale
    qs, R = [], [[jnp.zeros(()) for _ in range(p)] for _ in range(p)]
    for j in range(p):
        v = A[:, j]
        for _ in range(2):  # twice is enough (Kahan–Parlett)
            for i, q in enumerate(qs):
                c = q @ v
                v = v - c * q
                R[i][j] = R[i][j] + c
        nrm = jnp.sqrt(v @ v)
        ok = nrm > 1e-8
        qs.append(jnp.where(ok, v / jnp.where(ok, nrm, 1.0), 0.0))
        R[j][j] = jnp.where(ok, nrm, 0.0)
    b = [-(q @ r) for q in qs]
    proj2 = sum(x * x for x in b)
    ds = [jnp.zeros(())] * p
    for j in reversed(range(p)):
        acc = b[j] - sum((R[j][k] * ds[k] for k in range(j + 1, p)), jnp.zeros(()))
        ds[j] = jnp.where(R[j][j] > 0, acc / jnp.where(R[j][j] > 0, R[j][j], 1.0), 0.0)
    delta = jnp.stack(ds) / scale
    return jnp.sqrt(proj2 / jnp.maximum(s2, 1e-300)), delta


#: The statistical stop also needs the Gauss–Newton step short in θ (max |δθ|; θ is log- or
#: logit-scaled, so 0.1 ≈ 10 % of a value): far from the optimum, where the loss is flat (a
#: fault line under the noise floor), the linear model promises little although a long step
#: would gain much.
_STEP_GUARD = 0.1

#: The stall stop: this many evaluations in a row (accepted or rejected) that lower the best
#: loss by less than ½ (`sigma_tol` s)², the loss change of a move of `sigma_tol` standard
#: errors about the optimum …
_STALL_EVALUATIONS = 4
#: … at a point whose Gauss–Newton step is short in θ and within this many standard errors.
_STALL_SIGMA = 1.0


class _LossRecording(optx.AbstractSearch):
    """A search that records ½‖r‖² of every point the solver evaluates (accepted or rejected)
    in its state, then defers to `inner` (the solver's own search).

    The loss history is kept in the solver's state rather than sent to the host by a callback:
    a compiled program with a host callback is never written to JAX's persistent compilation
    cache, so a callback here would make every fit compile anew in every process. The search
    sees every evaluation (``f_eval_info``, the first one at the starting point included), so
    the history is the same as a callback on the residual function would give, up to
    `length` entries (the solver's step limit + 1)."""

    inner: optx.AbstractSearch
    length: int = eqx.field(static=True)

    def init(self, y, f_info_struct):
        return (self.inner.init(y, f_info_struct), jnp.full(self.length, jnp.nan),
                jnp.zeros((), jnp.int32))

    def step(self, first_step, y, y_eval, f_info, f_eval_info, state):
        inner_state, losses, count = state
        loss = 0.5 * jnp.sum(f_eval_info.residual ** 2)
        losses = losses.at[jnp.minimum(count, self.length - 1)].set(loss)
        step_size, accept, result, inner_state = self.inner.step(
            first_step, y, y_eval, f_info, f_eval_info, inner_state)
        return step_size, accept, result, (inner_state, losses, count + 1)


def _stalled(losses, count, s2, sigma_tol: float):
    """Whether the last `_STALL_EVALUATIONS` of the `count` recorded losses (½‖r‖² of every
    evaluation, :class:`_LossRecording`) all failed to lower the best loss before them by
    ½ (`sigma_tol`)² `s2`."""
    idx = jnp.arange(losses.shape[0], dtype=count.dtype)
    first = count - _STALL_EVALUATIONS
    finite = jnp.isfinite(losses)
    before = jnp.min(jnp.where((idx < first) & finite, losses, jnp.inf))
    recent = jnp.min(jnp.where((idx >= first) & (idx < count) & finite, losses, jnp.inf))
    return (first > 0) & (count <= losses.shape[0]) & (
        recent > before - 0.5 * sigma_tol ** 2 * s2)


def _noise_stopping(base):
    """`base` (an optimistix Gauss–Newton-type solver class) with two noise-aware stopping
    rules added; after each step it also stops when, at the last accepted point, the
    Gauss–Newton step is short in θ (`_STEP_GUARD`) and either

    - :func:`gauss_newton_step_in_sigma` is below `sigma_tol` (the statistical stop), or
    - it is below `_STALL_SIGMA` and the last `_STALL_EVALUATIONS` evaluations did not lower
      the loss by ½ (`sigma_tol` s)² (:func:`_stalled`): the loss is then flat to within the
      ODE solver's own noise, which the linear model cannot see (its step aims at that noise,
      and the steps towards it are rejected or gain nothing).

    ``sigma_tol = 0`` leaves `base`'s behaviour unchanged."""

    class NoiseStopping(base):
        sigma_tol: float = eqx.field(static=True, default=0.0)

        def __init__(self, rtol, atol, norm, sigma_tol: float, history: int):
            super().__init__(rtol=rtol, atol=atol, norm=norm)
            self.sigma_tol = sigma_tol
            self.search = _LossRecording(self.search, history)

        def step(self, fn, y, args, options, state, tags):
            y, state, aux = super().step(fn, y, args, options, state, tags)
            if self.sigma_tol > 0:
                f_info = state.f_info
                r = f_info.residual
                J = f_info.jac.as_matrix()
                in_sigma, delta = _gauss_newton_step(r, J)
                _, losses, count = state.search_state
                s2 = jnp.sum(r * r) / max(J.shape[0] - J.shape[1], 1)
                stalled = (in_sigma < _STALL_SIGMA) & _stalled(losses, count, s2, self.sigma_tol)
                near = ((in_sigma < self.sigma_tol) | stalled) & (
                    jnp.max(jnp.abs(delta)) < _STEP_GUARD)
                # before the first accepted step f_info holds zeros (s² = 0): never stop there
                near = near & (state.num_accepted_steps > 0)
                state = eqx.tree_at(lambda s: s.terminate, state, state.terminate | near)
            return y, state, aux

    NoiseStopping.__name__ = NoiseStopping.__qualname__ = base.__name__
    return NoiseStopping


_SOLVER_CLASSES = {"lm": _noise_stopping(optx.LevenbergMarquardt),
                   "gauss-newton": _noise_stopping(optx.GaussNewton),
                   "dogleg": _noise_stopping(optx.Dogleg)}


def _make_solver(name: str, rtol: float, atol: float, sigma_tol: float, history: int):
    """The optimistix solver, with two stopping rules (either one stops it):

    - the Cauchy test (both the step in θ and the change of the residuals below
      ``atol + rtol |·|``), with the RMS norm, not optimistix's default max norm: the residuals
      carry the ODE solver's own noise (two solves of one θ differ by up to 1e-5 at rtol 1e-5,
      2e-4 between rtol 1e-4 and 1e-5, on a 4 s record, measured before
      `SolverOptions.rate_scale_hz`; the present defaults' error is ~4× larger), so a max over ~2000 points against
      an atol of 1e-6 was met only by chance: fits ran to `max_steps`;
    - the statistical test (`sigma_tol` > 0): the Gauss–Newton step from the last accepted
      point is below `sigma_tol` standard errors (:func:`gauss_newton_step_in_sigma`): going
      on cannot move the estimate by a meaningful fraction of its uncertainty. Without it, a
      fit near its optimum spends steps chasing the ODE solver's noise in the residuals (4 s
      record, 3 parameters: the loss settled to 1e-5 after 4–5 steps, the Cauchy test stopped
      it after 13–19; benchmarks/README.md "Fit");
    - the stall test (with `sigma_tol` > 0, :func:`_noise_stopping`): the step is within
      `_STALL_SIGMA` standard errors and the last `_STALL_EVALUATIONS` evaluations did not
      lower the loss by ½ (`sigma_tol` s)². Where the ODE solver's noise in the loss exceeds
      that amount, the statistical test is met only by chance (a 4 s record's fit sat at its
      minimum from step 3 and stopped at step 30 on the Cauchy test).

    The loss of the first `history` residual evaluations is kept in the solver's state
    (:class:`_LossRecording`, read by :func:`_outcome`)."""
    if name not in _SOLVER_CLASSES:
        raise SettingsError(f"solver must be one of {SOLVERS}, got {name!r}")
    return _SOLVER_CLASSES[name](rtol=rtol, atol=atol, norm=optx.rms_norm, sigma_tol=sigma_tol,
                                 history=history)


def _outcome(sol):
    """``(θ, converged, steps, loss, r, J, losses, n, defect)`` of an optimistix
    Gauss–Newton-type solution; ``losses[:n]`` are the losses of the residual evaluations, in
    order, from :class:`_LossRecording` in the solver's search state, and `defect` the
    periodicity defect at θ (:meth:`Problem.simulated`).

    The residuals, Jacobian and defect come from the solver's state: they belong to the last
    accepted point, which is the returned value (optimistix keeps ``f_info`` and the auxiliary
    output of the accepted ``y``), so neither the final loss, the uncertainty's Jacobian nor
    the periodicity check costs another simulation. With
    forward-mode Jacobians the state holds ``t ↦ J t`` (:func:`_residuals_fwd`); materialising
    it applies that product to the identity, no solve."""
    f_info = sol.state.f_info
    r = f_info.residual
    J = f_info.jac.as_matrix()
    _, losses, count = sol.state.search_state  # _LossRecording's (inner, losses, count)
    count = jnp.minimum(count, losses.shape[0])
    return (sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"],
            0.5 * jnp.sum(r * r), r, J, losses, count, sol.state.aux)


def _least_squares(fn, solver, theta0, problem, jac: str, max_steps: int):
    """One `optimistix.least_squares` refinement from `theta0` (Jacobian in forward mode for
    ``jac="fwd"``, else reverse), returning :func:`_outcome` of its solution."""
    sol = optx.least_squares(fn, solver, theta0, args=problem, has_aux=True,
                             options=dict(jac="fwd" if jac == "fwd" else "bwd"),
                             max_steps=max_steps, throw=False)
    return _outcome(sol)


@eqx.filter_jit
def _refine(thetas, problem: Problem, solver_name: str, rtol: float, atol: float, jac: str,
            max_steps: int, sigma_tol: float = 0.0, batch: str = "vmap"):
    solver = _make_solver(solver_name, rtol, atol, sigma_tol, history=max_steps + 1)
    residuals = _residual_fn(jac)

    def one(theta0):
        return _least_squares(residuals, solver, theta0, problem, jac, max_steps)

    if thetas.shape[0] == 1:
        # one start: not vmapped. Under vmap (even of one) the ODE solve's while-loop predicate
        # is batched, and JAX then runs every step of it as selects over the whole carry.
        return jax.tree.map(lambda x: x[None], one(thetas[0]))
    return _over_batch(one, batch, thetas)


# ------------------------------------------------------------------------------------ result
@dataclasses.dataclass
class FitResult:
    """Outcome of :func:`fit`.

    - `names`, `values` (SI, dict), `theta` (unconstrained optimum), `initial` (SI, dict);
    - `uncertainty` (:class:`dtwin.identify.uncertainty.Uncertainty`, or None);
    - `loss` (½‖r‖² at the optimum), `loss_history` (½‖r‖² at every residual evaluation of the
      solver from the chosen start: the loss over iterations, rejected trial steps included), `start_losses` (the batched multi-start evaluation), `starts` (θ),
      `refined` (per refined start: θ, converged, steps, loss);
    - `converged`, `at_bound` (names), `message`, `iterations` (solver steps), `wall_time` (s),
      `operating_points` (Hz per record), `problem` (for figures and re-evaluation),
      `residuals` and `jacobian` (the residual vector and its Jacobian in θ at the optimum,
      from the solver's last accepted step);
    - `relocations`: each time the fit went on from a point of lower loss that a severity's
      profile or a stiffness's scan passed (the first optimum was a local one): the
      parameter's name (``profile_of``), ``by`` (``"profile"`` or ``"scan"``) and the loss
      before and after;
    - `excitation`: for a fault severity fitted with both ends of a calibrated spec's
      excitation/response split (:mod:`dtwin.identify.split`), the one reported
      (:data:`~dtwin.identify.split.SPLIT_CALIBRATED` or
      :data:`~dtwin.identify.split.SPLIT_STIFFNESS`), and `splits`: a row per split (loss,
      values, intervals, accepted); empty otherwise.
    """

    names: tuple[str, ...]
    values: dict[str, float]
    theta: np.ndarray
    initial: dict[str, float]
    uncertainty: Uncertainty | None
    loss: float
    loss_history: list[float]
    start_losses: np.ndarray
    starts: np.ndarray
    refined: list[dict[str, Any]]
    converged: bool
    at_bound: list[str]
    message: str
    iterations: int
    wall_time: float
    operating_points: list[dict[str, float]]
    problem: Problem | None = dataclasses.field(default=None, repr=False)
    residuals: np.ndarray | None = dataclasses.field(default=None, repr=False)
    jacobian: np.ndarray | None = dataclasses.field(default=None, repr=False)
    relocations: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    excitation: str = ""
    splits: list[dict[str, Any]] = dataclasses.field(default_factory=list)

    @property
    def not_determined(self) -> dict[str, str]:
        return {} if self.uncertainty is None else dict(self.uncertainty.not_determined)

    def interval(self, name: str) -> tuple[float, float]:
        i = self.names.index(name)
        lo, hi = self.uncertainty.interval[i]
        return float(lo), float(hi)

    @property
    def widened(self) -> float:
        """Factor the intervals were widened by for lack of fit (1: none;
        :mod:`dtwin.identify.uncertainty`, "Lack of fit")."""
        return 1.0 if self.uncertainty is None else float(self.uncertainty.widened)

    def status(self, name: str) -> str:
        """``NOT DETERMINED`` (``NOT DETERMINED: the model does not fit this record (loss N× the
        noise)`` above :data:`~dtwin.identify.uncertainty.MODEL_FORM_LIMIT`), ``unconverged``,
        ``widened ×k for lack of fit`` (the loss stands
        well above the noise: a model-form error of that size could move the value, so it is
        never called ok) or ``ok``; empty without uncertainty."""
        if self.uncertainty is None:
            return ""
        if name in self.uncertainty.not_determined:
            why = self.uncertainty.not_determined[name]
            return f"NOT DETERMINED: {why}" if why.startswith(MODEL_FORM_REASON) else \
                "NOT DETERMINED"
        if not self.converged:
            return "unconverged"
        if self.widened > 1.0:
            return f"widened ×{self.widened:.2g} for lack of fit"
        if not self.uncertainty.white:
            return f"residuals not white (p = {self.uncertainty.whiteness_p:.1g})"
        return "ok"

    def table(self) -> str:
        """A readable table: value, 95 % interval, determined or not."""
        rows = [f"{'parameter':<18} {'initial':>12} {'fitted':>12} {'95 % interval':>28}  status"]
        for i, n in enumerate(self.names):
            if self.uncertainty is not None:
                lo, hi = self.uncertainty.interval[i]
                iv = f"[{lo:.5g}, {hi:.5g}]"
                st = self.status(n)
            else:
                iv, st = "", ""
            rows.append(f"{n:<18} {self.initial[n]:>12.5g} {self.values[n]:>12.5g} {iv:>28}  {st}")
        rows.append(f"loss {self.loss:.5g}, {self.iterations} iterations, "
                    f"{self.wall_time:.1f} s, "
                    + ("converged" if self.converged else f"NOT converged ({self.message})")
                    + (f"; at bound: {', '.join(self.at_bound)}" if self.at_bound else ""))
        if self.converged and self.message != "converged":
            rows.append(self.message.removeprefix("converged; "))
        for m in self.relocations:
            rows.append(f"local optimum left: the {m['by']} of {m['profile_of']} passed a point "
                        f"of lower loss; refined from it, loss {m['loss_before']:.5g} → "
                        f"{m['loss_after']:.5g}")
        for row in self.splits:
            mark = "reported" if row["excitation"] == self.excitation else \
                "not rejected: intervals over both" if row["accepted"] else "rejected"
            vals = ", ".join(f"{n} {row['values'][n]:.5g}" for n in self.names)
            low = (f" (with the low band, not fitted: {row['low_band_loss']:.5g})"
                   if "low_band_loss" in row else "")
            rows.append(f"excitation/response split {row['excitation']!r}: loss "
                        f"{row['loss']:.5g}{low}, {vals} ({mark})")
        u = self.uncertainty
        if u is not None and np.isfinite(u.lack_of_fit):
            rows.append(f"lack of fit: loss {u.lack_of_fit:.3g}× what the noise alone leaves"
                        + (f"; every interval widened ×{u.widened:.3g} (covariance × the ratio: "
                           "a model-form error of this size moves the estimates)"
                           if u.widened > 1.0 else ""))
        for n, why in self.not_determined.items():
            rows.append(f"  {n}: not determined by these data ({why})")
        return "\n".join(rows)

    def to_dict(self) -> dict[str, Any]:
        out = {
            "names": list(self.names), "values": self.values, "initial": self.initial,
            "theta": self.theta.tolist(), "loss": self.loss, "loss_history": self.loss_history,
            "start_losses": self.start_losses.tolist(), "refined": self.refined,
            "converged": self.converged, "at_bound": self.at_bound, "message": self.message,
            "iterations": self.iterations, "wall_time_s": self.wall_time,
            "operating_points": self.operating_points, "relocations": self.relocations,
            "excitation": self.excitation, "splits": self.splits,
        }
        if self.uncertainty is not None:
            out["uncertainty"] = self.uncertainty.to_dict()
            out["intervals_95"] = {n: list(map(float, self.uncertainty.interval[i]))
                                   for i, n in enumerate(self.names)}
            out["not_determined"] = dict(self.uncertainty.not_determined)
        return out

    def spectra(self):
        """Per record: (freqs, measured, fitted) linear levels at the fitted points (numpy).

        The fitted levels come from the residual vector at the optimum, which holds them: a
        record's first residuals are ``weight (log fitted − log measured)`` at its points
        (:func:`dtwin.identify.residuals.observation_residuals`), so nothing is simulated
        again. Without residuals (or with a failed point in them) the twin is simulated at the
        optimum."""
        levels = self._levels_from_residuals()
        if levels is not None:
            return levels
        p = self.problem
        sigs, values = p.signals(jnp.asarray(self.theta))
        gain = p.pset.gain(values)
        out = []
        for s, o in zip(sigs, p.observations, strict=True):
            model, meas = fitted_levels(s, o, gain)
            out.append((np.asarray(o.freqs), meas, model))
        return out

    def _levels_from_residuals(self):
        """:meth:`spectra` read from `residuals`; None when they cannot give it."""
        p, r = self.problem, self.residuals
        if r is None or p is None:
            return None
        r = np.asarray(r, dtype=np.float64)
        out, off = [], 0
        for o in p.observations:
            n = residual_count(o)
            levels = levels_from_residuals(r[off: off + n], o)
            if levels is None:
                return None
            out.append((np.asarray(o.freqs), levels[1], levels[0]))
            off += n
        return out if off + len(p.pset.priors) == r.shape[0] else None


# ------------------------------------------------------------------------------------ fit
def _as_twin(spec_or_twin, kind: str | None):
    if isinstance(spec_or_twin, Twin):
        return spec_or_twin
    spec = spec_or_twin if isinstance(spec_or_twin, Spec) else load_spec(spec_or_twin)
    return build_twin(spec, kind=twin_kind(spec, kind))


def _spec_of(spec_or_twin) -> Spec | None:
    """The spec (None: a twin, which carries no geometry to check a fitted value against)."""
    if isinstance(spec_or_twin, Twin):
        return None
    return spec_or_twin if isinstance(spec_or_twin, Spec) else load_spec(spec_or_twin)


def _calibrated_spec(spec_or_twin) -> Spec | None:
    """The spec when it was written by ``dtwin calibrate`` (None: a twin or an uncalibrated
    spec)."""
    spec = _spec_of(spec_or_twin)
    return spec if spec is not None and is_calibrated(spec) else None


def _checked_stiffness(unc, pset, theta, spec_or_twin):
    """`unc` with a free mesh stiffness that the spec's gear pair cannot have flagged, and
    the parameters fitted beside it (:mod:`dtwin.identify.plausibility`); the spec is read only
    when a mesh stiffness is free."""
    if unc is None or not any(n in MESHES for n in pset.free):
        return unc
    return flag_implausible(unc, pset.as_dict(theta), _spec_of(spec_or_twin))


def make_problem(
    records,
    spec_or_twin,
    free: Sequence[str] | str | ParameterSet,
    *,
    kind: str | None = None,
    f_sun: float | Sequence[float | None] | None = None,
    runup: tuple[float, float] | Sequence[tuple[float, float] | None] | None = None,
    features: Features | Sequence[Features] | None = None,
    weights: Sequence[float] | None = None,
    initial: Mapping[str, float] | None = None,
    fixed: Mapping[str, float] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    priors: Mapping[str, tuple[float, float]] | None = None,
    channel: int | str = 0,
    discard: float = 0.05,
    oversample: int = 4,
    rtol: float = 1e-5,
    atol: float = 1e-5,
    jac: str = "fwd",
    periodic: str = "auto",
) -> tuple[Problem, list[dict[str, float]]]:
    """Checks, operating points and observations → a :class:`Problem` (no simulation yet).

    Arguments as :func:`fit`; `periodic`: ``"auto"`` (default: a constant-speed record whose
    settling time (0.1 s) and the gear set's period fit in 3/4 of it is simulated over those
    only and tiled, ``dtwin.simulate.SolverOptions.periodic``; run-ups and twins whose response is not
    periodic are simulated in full; :func:`fit` settles longer where the tiled response at its
    optimum was not periodic) or ``"off"`` (always in full).
    **Returns:** ``(problem, operating_points)``.
    """
    if isinstance(free, ParameterSet):
        pset = free
    else:
        # names first: an unknown name fails before the twin is even built
        names = [s.strip() for s in free.split(",")] if isinstance(free, str) else list(free)
        for n in names:
            lookup(n)
        for n in list(fixed or {}) + list(initial or {}):
            lookup(n)
    if jac not in ("fwd", "rev"):
        raise SettingsError(f"jac must be 'fwd' or 'rev', got {jac!r}")
    if not isinstance(records, (list, tuple)):
        records = [records]
    if not records:
        raise FitError("no record to fit")
    twin = _as_twin(spec_or_twin, kind)
    if not isinstance(free, ParameterSet):
        pset = ParameterSet.build(names, twin, initial=initial, fixed=fixed, bounds=bounds,
                                  priors=priors)
    twin = pset.prepare(twin)
    n = len(records)
    f_list = list(f_sun) if isinstance(f_sun, (list, tuple)) else [f_sun] * n
    r_list = list(runup) if isinstance(runup, list) else [runup] * n
    feat_list = list(features) if isinstance(features, (list, tuple)) else [features] * n
    w_list = list(weights) if weights is not None else [1.0] * n
    if not (len(f_list) == len(r_list) == len(feat_list) == len(w_list) == n):
        raise FitError("f_sun, runup, features and weights need one entry per record")
    nominal = nominal_speed(spec_or_twin)
    frf = _sensor_response(spec_or_twin)
    obs, ops = [], []
    for i, rec in enumerate(records):
        # cheap input checks before the speed estimate
        x = np.asarray(rec.channel(channel))
        if not np.all(np.isfinite(x)):
            bad = np.flatnonzero(~np.isfinite(x))
            raise RecordError(f"record {i} holds {bad.size} NaN/inf samples (first at sample "
                              f"{bad[0]}); clean or cut it before identification")
        if r_list[i] is not None:
            prof = estimate_speed_profile(rec, twin, r_list[i], channel=channel)
            f0, f1 = prof.f_start, prof.f_end
            ops.append({"f_sun_start": f0, "f_sun_end": f1, "method": prof.method})
        else:
            if f_list[i] is None and nominal is not None:
                _check(rec, twin, nominal, channel)  # rate and length, before the estimate
            op = resolve_speed(rec, spec_or_twin, f_list[i], channel=channel, check=False,
                               fallback=False, required=False)
            if op is None:
                raise FitError("no input speed: pass f_sun, a record with a tachometer, or a "
                               "spec with operating.f_sun")
            f0 = op.f_sun
            ops.append({"f_sun": f0, "method": "given"} if op.method == "given" else
                       {"f_sun": f0, "std_f_sun": op.std_f_sun, "method": op.method})
            f1 = None
        ob = observe(rec, twin, f_sun=f0, f_end=f1, features=feat_list[i], channel=channel,
                     weight=w_list[i], discard=discard, oversample=oversample)
        obs.append(dataclasses.replace(ob, frf_hz=frf[0], frf_db=frf[1]) if frf else ob)
    if periodic not in ("off", "auto"):
        raise SettingsError(f"periodic must be 'off' or 'auto', got {periodic!r}")
    problem = Problem(twin, pset, tuple(obs), rtol=rtol, atol=atol,
                      adjoint="forward" if jac == "fwd" else "reverse", periodic=periodic)
    return problem, ops


def _sensor_response(spec_or_twin) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """The calibrated sensor response ``(frf_hz, frf_db)`` of a spec (None: flat, or a twin)."""
    if isinstance(spec_or_twin, Twin):
        return None
    spec = spec_or_twin if isinstance(spec_or_twin, Spec) else load_spec(spec_or_twin)
    s = spec["sensor"]
    return None if s["frf_hz"] is None else (tuple(s["frf_hz"]), tuple(s["frf_db"]))


def start_grid(p: int, n_starts: int, spread: float, seed: int) -> np.ndarray:
    """θ starts: 0 first, then the corners and edges of ``{-spread, 0, spread}^p`` sub-sampled."""
    pts = np.array(list(itertools.product((-spread, 0.0, spread), repeat=p)), dtype=float)
    pts = pts[np.any(pts != 0, axis=1)]
    rng = np.random.default_rng(seed)
    rng.shuffle(pts)
    return np.concatenate([np.zeros((1, p)), pts[: max(n_starts - 1, 0)]])


def fit(
    records,
    spec_or_twin,
    free: Sequence[str] | str | ParameterSet,
    *,
    solver: str = "lm",
    starts: int | np.ndarray | Sequence[Mapping[str, float]] = 1,
    refine: int = 1,
    spread: float = 0.3,
    seed: int = 0,
    jac: str = "fwd",
    max_steps: int = 40,
    tol: float = 1e-4,
    sigma_tol: float = SIGMA_TOL,
    batch: str = "auto",
    uncertainty: bool = True,
    scan: bool = True,
    confounding: bool = True,
    progress: bool = False,
    throw: bool = False,
    splits: bool | None = None,
    problem: Problem | None = None,
    **problem_kwargs: Any,
) -> FitResult:
    """Fit the free parameters of a twin to one or several records.

    **Arguments:**

    - `records`: a `dtwin.io.Record` or a list (fitted jointly).
    - `spec_or_twin`: a spec (path, mapping, `Spec`; built with ``kind``: default the kind a
      calibrated spec was calibrated with, otherwise torsional, :func:`dtwin.build.twin_kind`)
      or a `Twin`.
    - `free`: registry names (list or ``"a,b,c"``) or a `ParameterSet`.
    - `solver`: ``lm`` (Levenberg–Marquardt), ``gauss-newton`` or ``dogleg``.
    - `starts`: number of grid starts (batched evaluation), or an array of θ starts ``(k, p)``,
      or a list of dicts of physical starting values; `refine`: how many of the best starts are
      refined (batched); `spread`: grid half-width in θ (0.3 ≈ ±30 % for log parameters).
    - `jac`: ``fwd`` (forward mode through diffrax) or ``rev``.
    - `max_steps`, `tol`: solver steps, and its rtol = atol on θ and on the residuals (RMS
      norm, :func:`_make_solver`).
    - `sigma_tol`: also stop when the Gauss–Newton step from the accepted point is below this
      many standard errors (:func:`gauss_newton_step_in_sigma`; 0 turns the test off).
    - `batch`: how the start grid and several refined starts run in their one compiled call,
      ``"auto"``, ``"vmap"`` or ``"map"`` (:func:`batch_mode`).
    - `uncertainty`: compute covariance, intervals and flags. When a severity's profile
      likelihood passes a point of lower loss than the optimum (by more than the χ²₁ 95 %
      level), the optimum was a local one: the solver goes on from that point (up to
      ``MAX_RELOCATIONS`` times) and the result lists it in `relocations`.
    - `scan`: with `uncertainty`, also scan the loss of each free stiffness, mass and inertia
      that the Gaussian analysis finds determined over a decade each side of the optimum (8
      points, two batched evaluations each): a point of lower loss is refitted from as above,
      a second minimum within the 95 % level flags the parameter
      (:mod:`dtwin.identify.uncertainty`, "Scan").
    - `confounding`: with a calibrated spec and a free stiffness, damping ratio, mass or
      inertia, flag the parameters the calibrated mesh excitation and load-share clearances
      confound (:mod:`dtwin.identify.confounding`; one more Jacobian with their columns).
    - `progress`: print the stages and losses (stderr).
    - `throw`: raise `FitError` when not converged or at a bound.
    - `splits`: with a calibrated spec whose mesh excitation or sensor response was calibrated,
      fit the free parameters again with the other end of its excitation/response split (the
      stiffness waveform's excitation, a flat response) and report the split of least loss
      (for a sun or ring fault, scored with the low band too, which the fits do not use:
      :func:`low_band_losses`), with intervals over both where the
      record cannot reject either (:mod:`dtwin.identify.split`); None: where a fault severity is free (a healthy record
      cannot tell the splits apart, a fault's sidebands can), True: for any parameters, False:
      never. Not with `problem`.
    - keyword arguments of :func:`make_problem`: ``f_sun``, ``runup``, ``features``,
      ``weights``, ``initial``, ``fixed``, ``bounds``, ``priors``, ``channel``, ``discard``,
      ``oversample``, ``kind``, ``rtol``, ``atol``, ``periodic``.

    **Returns:** :class:`FitResult`.
    """
    if solver not in SOLVERS:
        raise SettingsError(f"solver must be one of {SOLVERS}, got {solver!r}")
    names = None if problem is not None or isinstance(free, ParameterSet) else check_free(free)
    other = None if names is None else other_split(spec_or_twin, names, splits)
    if other is not None:  # both ends of the calibration's split (dtwin.identify.split)
        kw = dict(solver=solver, starts=starts, refine=refine, spread=spread, seed=seed, jac=jac,
                  max_steps=max_steps, tol=tol, sigma_tol=sigma_tol, batch=batch,
                  uncertainty=uncertainty, scan=scan, confounding=confounding,
                  progress=progress, splits=False, **problem_kwargs)
        pair = [(spec_or_twin, fit(records, spec_or_twin, free, **kw)),
                (other, fit(records, other, free, **kw))]
        res = choose_split([(SPLIT_CALIBRATED, pair[0][1]), (SPLIT_STIFFNESS, pair[1][1])],
                           low_band_losses(pair, records, names, problem_kwargs))
        if throw and (not res.converged or res.at_bound):
            raise FitError(res.message)
        return res
    mode = batch_mode(batch)
    t0 = time.perf_counter()
    if problem is None:
        problem, ops = make_problem(records, spec_or_twin, free, jac=jac, **problem_kwargs)
    else:
        ops = []
    pset = problem.pset
    p = pset.size
    def say(m):
        if progress:
            print(f"[{time.perf_counter() - t0:7.1f} s] {m}", file=sys.stderr, flush=True)

    say(pset.summary())
    if isinstance(starts, (int, np.integer)):
        thetas = start_grid(p, int(starts), spread, seed)
    elif len(starts) and isinstance(starts[0], Mapping):
        thetas = np.stack([pset.theta(s) for s in starts])
    else:
        thetas = np.atleast_2d(np.asarray(starts, dtype=float))
    thetas = jnp.asarray(thetas)
    if thetas.shape[0] > 1:
        say(f"evaluating {thetas.shape[0]} starts in one batch …")
        losses = np.asarray(_batched_loss(thetas, problem, mode))
    else:
        losses = np.asarray([np.nan])
    order = np.argsort(np.where(np.isfinite(losses), losses, np.inf)) if thetas.shape[0] > 1 \
        else np.arange(1)
    chosen = thetas[np.asarray(order[: max(1, refine)])]
    if thetas.shape[0] > 1:
        say(f"start losses: {np.array2string(losses, precision=4)}; refining {chosen.shape[0]}")
    else:
        say("one start: refining it (its loss is the first of the history)")
    _heap.before_first_fit()
    problem, out, settle_notes = _settled_fit(
        problem, lambda prob, th: _refine(th, prob, solver, tol, tol, jac, max_steps, sigma_tol,
                                          mode), chosen,
        lambda out: np.asarray(out[-1])[_best(np.asarray(out[3]))], say)
    th, ok, steps, fl, rs, Js, hist, n_hist, _ = out
    th, ok, steps, fl = (np.asarray(th), np.asarray(ok), np.asarray(steps), np.asarray(fl))
    refined = [{"theta": th[i].tolist(), "converged": bool(ok[i]), "steps": int(steps[i]),
                "loss": float(fl[i]), "values": pset.as_dict(th[i])} for i in range(th.shape[0])]
    best = _best(fl)
    theta = th[best]
    say(f"refined losses: {np.array2string(fl, precision=5)}; best {fl[best]:.6g} after "
        f"{int(steps[best])} steps")
    unc = None
    relocated = []
    rs, Js, hist, n_hist = (np.asarray(a) for a in (rs, Js, hist, n_hist))
    if uncertainty:
        groups = point_groups(problem.observations)
        expected = expected_noise_rss(problem.observations)
    while uncertainty:
        # the residuals and Jacobian at the optimum from the solver's last accepted step
        unc = analyse(pset, theta, rs[best], Js[best], groups,
                      n_profiled_gains=problem.n_profiled_gains,
                      profile_fn=lambda ts: _batched_residuals(jnp.asarray(ts), problem, mode),
                      expected_rss=expected, scan=_scanned(pset) if scan else (),
                      reach=window_reach(problem.observations))
        if unc.better is None or len(relocated) >= MAX_RELOCATIONS:
            break
        # a severity's profile or a stiffness's scan passed a point of lower loss: the optimum
        # was a local one, and the solver goes on from that point (the same compiled refinement)
        name, th_b, _ = unc.better
        say(f"the profile or scan of {name} passed a point of lower loss ({name} = "
            f"{pset.as_dict(th_b)[name]:.4g}): refining from it")
        out = _refine(jnp.asarray(th_b)[None, :], problem, solver, tol, tol, jac, max_steps,
                      sigma_tol, mode)
        th2, ok2, steps2, fl2, rs2, Js2, hist2, n_hist2, _ = (np.asarray(a) for a in out)
        refined.append({"theta": th2[0].tolist(), "converged": bool(ok2[0]),
                        "steps": int(steps2[0]), "loss": float(fl2[0]),
                        "values": pset.as_dict(th2[0]), "from_profile_of": name})
        if not fl2[0] < fl[best]:
            break
        relocated.append((name, float(fl[best]), float(fl2[0]),
                          "scan" if name in unc.scanned else "profile"))
        th, ok, steps, fl, rs, Js, hist, n_hist = (
            np.concatenate([a, b]) for a, b in zip((th, ok, steps, fl, rs, Js, hist, n_hist),
                                                   (th2, ok2, steps2, fl2, rs2, Js2, hist2,
                                                    n_hist2), strict=True))
        best = th.shape[0] - 1
        theta = th[best]
        say(f"refined from that point: loss {fl[best]:.6g} after {int(steps[best])} steps")
    if uncertainty:
        spec = _calibrated_spec(spec_or_twin)
        if confounding and spec is not None and needs_check(pset.free, spec):
            say("checking the fitted values against the calibration (one more Jacobian, with "
                f"its {len(calibrated_excitation(spec))} excitation coefficients and load-share "
                "clearances free) …")
            unc, _ = calibration_confounding(problem, theta, unc, spec, groups=groups,
                                             expected_rss=expected, jacobian=_jacobian)
        unc = _checked_stiffness(unc, pset, theta, spec_or_twin)
    at_bound = pset.at_bound(theta)
    hit_limit = int(steps[best]) >= max_steps
    converged = bool(ok[best]) and not hit_limit
    history = [float(v) for v in np.asarray(hist[best])[: int(n_hist[best])]]
    if thetas.shape[0] == 1 and history:  # the loss at the one start: the solver's first call
        losses = np.asarray([history[0]])
    msgs = []
    if hit_limit:
        msgs.append(f"stopped at the step limit ({int(steps[best])} of max_steps={max_steps}) "
                    "before the stopping rule was met; raise max_steps (--max-steps), use more "
                    "starts, or free fewer parameters")
    elif not converged:
        msgs.append(f"not converged after {int(steps[best])} steps (max_steps={max_steps}); "
                    "raise max_steps, use more starts, or free fewer parameters")
    if at_bound:
        msgs.append(f"parameters at a bound: {', '.join(at_bound)} (the data push them out of "
                    "their range: check the spec, the bounds or the model)")
    message = "; ".join((msgs or ["converged"]) + settle_notes)
    res = FitResult(
        names=pset.free, values=pset.as_dict(theta), theta=theta,
        initial=pset.as_dict(np.zeros(p)), uncertainty=unc, loss=float(fl[best]),
        loss_history=history or [float(fl[best])],

        start_losses=losses, starts=np.asarray(thetas), refined=refined, converged=converged,
        at_bound=at_bound, message=message, iterations=int(steps[best]),
        wall_time=time.perf_counter() - t0, operating_points=ops, problem=problem,
        residuals=np.asarray(rs[best]), jacobian=np.asarray(Js[best]),
        relocations=[{"profile_of": n, "loss_before": a, "loss_after": b, "by": by}
                     for n, a, b, by in relocated],
    )
    say(res.table())
    if throw and (not converged or at_bound):
        raise FitError(message)
    return res


def _scanned(pset: ParameterSet) -> tuple[str, ...]:
    """The free ``log`` parameters of `pset` in :data:`SCANNED_SECTIONS`."""
    return tuple(n for n, tr in zip(pset.free, pset.transforms, strict=True)
                 if tr == "log" and n in REGISTRY and REGISTRY[n].section in SCANNED_SECTIONS)


def check_free(free: Sequence[str] | str) -> list[str]:
    """Registry names of a `--free` list, checked (unknown → `ParameterError`)."""
    names = [s.strip() for s in free.split(",") if s.strip()] if isinstance(free, str) else list(free)
    if not names:
        raise ParameterError("no free parameter given")
    for n in names:
        lookup(n)
    return names


# ------------------------------------------------------------------------------------ batch
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
def _refine_records(thetas, stacked: Problem, solver_name: str, rtol: float, atol: float,
                    jac: str, max_steps: int, sigma_tol: float = 0.0, batch: str = "vmap"):
    solver = _make_solver(solver_name, rtol, atol, sigma_tol, history=max_steps + 1)
    arrays, static = eqx.partition(stacked, eqx.is_array)

    def one(theta0, arr):
        prob = eqx.combine(arr, static)
        return _least_squares(_residual_fn(jac), solver, theta0, prob, jac, max_steps)

    return _over_batch(one, batch, thetas, arrays)


def fit_batch(
    records: Sequence,
    spec_or_twin,
    free: Sequence[str] | str,
    *,
    solver: str = "lm",
    jac: str = "fwd",
    max_steps: int = 40,
    tol: float = 1e-4,
    sigma_tol: float = SIGMA_TOL,
    batch: str = "auto",
    uncertainty: bool = True,
    confounding: bool = True,
    splits: bool | None = None,
    **problem_kwargs: Any,
) -> list[FitResult]:
    """Fit many records of one gearbox type in one compiled call (one start each, θ = 0):
    ``vmap`` over the records on a GPU, ``jax.lax.map`` on a CPU (`batch`, :func:`batch_mode`). Records must share length, rate and speed to 0.1 Hz (:func:`stack_problems`);
    per-record keyword lists (``f_sun``…) are not taken here: pass scalars. Uncertainties come
    from the residuals and Jacobian of each record's last accepted LM step, checked against a
    spec's calibration as in :func:`fit` (`confounding`); no severity is profiled and no
    stiffness scanned (:func:`fit` does both). `splits`: as for :func:`fit` (both ends of a
    calibrated spec's excitation/response split, a batch each, chosen per record).
    **Returns:** one :class:`FitResult` per record, as :func:`fit` would."""
    names = check_free(free)
    other = other_split(spec_or_twin, names, splits)
    if other is not None:  # both ends of the calibration's split (dtwin.identify.split)
        kw = dict(solver=solver, jac=jac, max_steps=max_steps, tol=tol, sigma_tol=sigma_tol,
                  batch=batch, uncertainty=uncertainty, confounding=confounding, splits=False,
                  **problem_kwargs)
        return [choose_split([(SPLIT_CALIBRATED, a), (SPLIT_STIFFNESS, b)],
                             low_band_losses([(spec_or_twin, a), (other, b)], rec, names,
                                             problem_kwargs))
                for rec, a, b in zip(records, fit_batch(records, spec_or_twin, free, **kw),
                                     fit_batch(records, other, free, **kw), strict=True)]
    t0 = time.perf_counter()
    made = [make_problem(r, spec_or_twin, free, jac=jac, **problem_kwargs) for r in records]
    problems = [m[0] for m in made]
    p = problems[0].pset.size
    thetas = jnp.zeros((len(problems), p))
    _heap.before_first_fit()

    def refine(settings: Problem, starts):
        # one structure: the records share length, rate, speed and so the settling time
        stacked = stack_problems([dataclasses.replace(
            pr, periodic=settings.periodic, periodic_settle=settings.periodic_settle)
            for pr in problems])
        return _refine_records(starts, stacked, solver, tol, tol, jac, max_steps, sigma_tol,
                               batch_mode(batch))

    settings, out, settle_notes = _settled_fit(problems[0], refine, thetas,
                                 lambda out: max((d for d in np.asarray(out[-1]) if np.isfinite(d)),
                                                 default=0.0), lambda m: None)
    problems = [dataclasses.replace(pr, periodic=settings.periodic,
                                    periodic_settle=settings.periodic_settle) for pr in problems]
    th, ok, steps, fl, rs, Js, hist, n_hist, _ = out
    th, ok, steps, fl = (np.asarray(th), np.asarray(ok), np.asarray(steps), np.asarray(fl))
    wall = time.perf_counter() - t0
    spec = _calibrated_spec(spec_or_twin)
    out = []
    for i, prob in enumerate(problems):
        pset = prob.pset
        unc = None
        if uncertainty:
            unc = analyse(pset, th[i], np.asarray(rs[i]), np.asarray(Js[i]),
                          point_groups(prob.observations),
                          n_profiled_gains=prob.n_profiled_gains,
                          expected_rss=expected_noise_rss(prob.observations),
                          reach=window_reach(prob.observations))
            if confounding and spec is not None and needs_check(pset.free, spec):
                unc, _ = calibration_confounding(
                    prob, th[i], unc, spec, groups=point_groups(prob.observations),
                    expected_rss=expected_noise_rss(prob.observations),
                    jacobian=_jacobian)
            unc = _checked_stiffness(unc, pset, th[i], spec_or_twin)
        at_bound = pset.at_bound(th[i])
        out.append(FitResult(
            names=pset.free, values=pset.as_dict(th[i]), theta=th[i],
            initial=pset.as_dict(np.zeros(p)), uncertainty=unc, loss=float(fl[i]),
            loss_history=[float(v) for v in np.asarray(hist[i])[: int(n_hist[i])]] or [float(fl[i])],
            start_losses=np.zeros(0),  # no start evaluated alone
            starts=np.zeros((1, p)), refined=[],
            converged=bool(ok[i]) and int(steps[i]) < max_steps, at_bound=at_bound,
            message="; ".join([
                "converged" if ok[i] and int(steps[i]) < max_steps else
                f"stopped at the step limit ({int(steps[i])} of max_steps={max_steps})"
                if int(steps[i]) >= max_steps else
                f"not converged after {int(steps[i])} steps"] + settle_notes),

            iterations=int(steps[i]), wall_time=wall, operating_points=made[i][1], problem=prob,
            residuals=np.asarray(rs[i]), jacobian=np.asarray(Js[i]),
        ))
    return out


def low_band_losses(fits: Sequence[tuple[Any, FitResult]], records, names: Sequence[str],
                    problem_kwargs: dict[str, Any]) -> list[float] | None:
    """Each fit's loss (½‖r‖²) over its own points and the low band of `records` (the fault's
    comb below the first mesh band, :func:`dtwin.identify.low_band.with_low_band`), at its fitted
    values: `fits` are ``(spec, FitResult)`` of one record set. The low band is where a small
    sun or ring fault makes its strongest lines and where the fit did not look, so it scores the
    splits on data the fits did not use. A fit on the DFT grid is scored with its own problem
    and the low band added; one in the order domain with a DFT-grid problem of the same record
    at the fitted values and operating point. None where it does not apply (the fits are then
    scored by their own losses): no sun or ring fault among `names` (:data:`LOW_BAND_FAULTS`), a
    run-up, a fit without uncertainty, or a score that could not be computed."""
    if not any(n in LOW_BAND_FAULTS for n in names):
        return None
    recs = list(records) if isinstance(records, (list, tuple)) else [records]
    channel = problem_kwargs.get("channel", 0)
    keep = {k: v for k, v in problem_kwargs.items()
            if k not in ("features", "weights", "f_sun", "initial", "runup")}
    out = []
    for spec, res in fits:
        prob = res.problem
        if prob is None or res.uncertainty is None or \
                any(o.kind != "spectrum" or o.ramp for o in prob.observations):
            return None
        theta = np.asarray(res.theta)
        if any(o.order_domain for o in prob.observations):
            f_sun = [op.get("f_sun") for op in res.operating_points]
            if len(f_sun) != len(recs) or any(f is None for f in f_sun):
                return None
            try:
                prob, _ = make_problem(recs, spec, list(res.names), initial=dict(res.values),
                                       f_sun=f_sun, features=Features(), **keep)
            except DtwinError:  # scored by the fits' own losses then
                return None
            theta = np.zeros_like(theta)
        if len(prob.observations) != len(recs):
            return None
        prob = with_low_band_problem(prob, recs, channel=channel)
        out.append(float(np.asarray(_batched_loss(jnp.asarray(theta)[None], prob, "map"))[0]))
    return out if all(np.isfinite(out)) else None
