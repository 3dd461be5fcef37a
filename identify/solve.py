"""How a :class:`~dtwin.identify.problem.Problem` is solved: the compiled least-squares refinement.

- residuals and their Jacobian: forward mode, with the tangents of only the parameters that
  change the twin riding through the ODE solve (:func:`value_and_jacfwd`), and one
  primal-and-tangents solve per Levenberg–Marquardt step (:func:`_residuals_fwd`); reverse mode
  on request;
- batches of starts or records in one compiled call (:func:`batch_mode`: ``vmap`` or
  ``jax.lax.map``);
- one ``optimistix.least_squares`` refinement per start (:func:`refine_starts`), its outcome read
  from the solver's state (:func:`outcome`), with the stopping rules of
  :mod:`dtwin.identify.stopping`;
- fitted again with a longer settling time while the fitted response is not periodic
  (:func:`settled_fit`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from dtwin.errors import SettingsError
from dtwin.simulation.simulate import settling_sequence

from .problem import Problem
from .stopping import make_solver

__all__ = ["BATCH_MODES", "batch_mode", "batched_loss", "batched_residuals", "best_start",
           "jacobian_at", "least_squares", "outcome", "over_batch", "refine_starts", "residual_fn",
           "settled_fit", "value_and_jacfwd"]


def settled_fit(problem: Problem, refine, starts, defect_of, say
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
    `dtwin.simulation.simulate.settling_sequence`, from where the last run ended (its start where that is
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


def best_start(losses) -> int:
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
    (benchmarks/README.md, "Moved from module docstrings (#52)")."""
    if batch not in BATCH_MODES:
        raise SettingsError(f"batch must be one of {BATCH_MODES}, got {batch!r}")
    if batch == "auto":
        return "map" if jax.default_backend() == "cpu" else "vmap"
    return batch


def over_batch(f, mode: str, *xs):
    """`f` over the leading axis of the arrays `xs`: ``jax.vmap`` or ``jax.lax.map``."""
    if mode == "vmap":
        return jax.vmap(f)(*xs)
    return jax.lax.map(lambda a: f(*a), xs)


@eqx.filter_jit
def batched_loss(thetas, problem: Problem, batch: str = "vmap"):
    return over_batch(lambda t: _loss(t, problem), batch, thetas)


@eqx.filter_jit
def batched_residuals(thetas, problem: Problem, batch: str = "vmap"):
    return over_batch(lambda t: problem.residuals(t), batch, thetas)


def value_and_jacfwd(theta, problem: Problem):
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
    """``(r, ∂r/∂θ, defect)``: :func:`value_and_jacfwd` and the periodicity defect of the
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
def jacobian_at(theta, problem: Problem):
    return value_and_jacfwd(theta, problem)


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


def residual_fn(jac: str):
    """The residual function handed to optimistix, returning ``(residuals, defect)`` (the
    defect as the solve's auxiliary output): `_residuals_fwd` for forward-mode Jacobians,
    `Problem.residuals_and_defect` for reverse mode."""
    if jac == "fwd":
        return lambda t, prob: _residuals_fwd(t, problem=prob)
    return lambda t, prob: prob.residuals_and_defect(t)



def outcome(sol):
    """``(θ, converged, steps, loss, r, J, losses, n, defect)`` of an optimistix
    Gauss–Newton-type solution; ``losses[:n]`` are the losses of the residual evaluations, in
    order, from :class:`~dtwin.identify.stopping.LossRecording` in the solver's search state, and `defect` the
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
    _, losses, count = sol.state.search_state  # LossRecording's (inner, losses, count)
    count = jnp.minimum(count, losses.shape[0])
    return (sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"],
            0.5 * jnp.sum(r * r), r, J, losses, count, sol.state.aux)


def least_squares(fn, solver, theta0, problem, jac: str, max_steps: int):
    """One `optimistix.least_squares` refinement from `theta0` (Jacobian in forward mode for
    ``jac="fwd"``, else reverse), returning :func:`outcome` of its solution."""
    sol = optx.least_squares(fn, solver, theta0, args=problem, has_aux=True,
                             options=dict(jac="fwd" if jac == "fwd" else "bwd"),
                             max_steps=max_steps, throw=False)
    return outcome(sol)


@eqx.filter_jit
def refine_starts(thetas, problem: Problem, solver_name: str, rtol: float, atol: float, jac: str,
            max_steps: int, sigma_tol: float = 0.0, batch: str = "vmap"):
    solver = make_solver(solver_name, rtol, atol, sigma_tol, history=max_steps + 1)
    residuals = residual_fn(jac)

    def one(theta0):
        return least_squares(residuals, solver, theta0, problem, jac, max_steps)

    if thetas.shape[0] == 1:
        # one start: not vmapped. Under vmap (even of one) the ODE solve's while-loop predicate
        # is batched, and JAX then runs every step of it as selects over the whole carry.
        return jax.tree.map(lambda x: x[None], one(thetas[0]))
    return over_batch(one, batch, thetas)

