"""Stopping rules of the least-squares fits.

**Fits of a twin** (:func:`dtwin.identify.fit.fit`): optimistix's Gauss–Newton-type solvers
(:data:`SOLVERS`) with the Cauchy test in the RMS norm and two noise-aware rules added
(:func:`make_solver`): the statistical stop (the Gauss–Newton step from the accepted point is
below `sigma_tol` standard errors, :func:`gauss_newton_step_in_sigma`) and the stall stop (the
loss no longer falls by more than the ODE solver's noise, :class:`LossRecording`).

**Fits that stall** (:class:`StallStopping`): optimistix's Levenberg–Marquardt stops on the
Cauchy test: both the step in the parameters and
the change of the residuals below ``atol + rtol |·|``. Along a direction the data hardly
determine, the parameters keep moving by ever smaller decreases of the loss, so that test never
holds and the fit runs to its step limit. :class:`StallStopping` also stops after an accepted
step (not the first) that lowered the loss by less than `loss_rtol` of itself.

Where it is used: the fold fits of discovery's statistic and its bootstrap (a non-negative
parameter fitted as ``θ = exp(u)`` whose optimum lies at θ = 0 walks ``u`` towards −∞), and the
fits of calibration (window and excitation terms that the records do not determine).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from dtwin.errors import SettingsError

__all__ = ["SIGMA_TOL", "SOLVERS", "StallStopping", "gauss_newton_step_in_sigma", "make_solver"]

SOLVERS = ("lm", "gauss-newton", "dogleg")
#: Default statistical stopping rule: stop when the optimum is within this many standard
#: errors of the accepted point (:func:`gauss_newton_step_in_sigma`). Above the ODE solver's
#: noise floor (benchmarks/README.md, "Moved from module docstrings (#52)"); a step of 0.1 σ moves no interval noticeably.
SIGMA_TOL = 0.1


class StallStopping(optx.LevenbergMarquardt):
    """`optimistix.LevenbergMarquardt` with the stall rule (module docstring).

    **Arguments:** `rtol`, `atol` (the Cauchy test, as optimistix); `loss_rtol`: the relative
    decrease of ½‖r‖² below which an accepted step stops the fit (0 leaves optimistix's rule
    alone). A fit it stops ends with ``RESULTS.successful``; one at the step limit still ends
    with ``RESULTS.max_steps_reached``.
    """

    loss_rtol: float = eqx.field(static=True)

    def __init__(self, rtol: float, atol: float, loss_rtol: float = 1e-6):
        super().__init__(rtol=rtol, atol=atol)
        self.loss_rtol = loss_rtol

    def step(self, fn, y, args, options, state, tags):
        y_new, new, aux = super().step(fn, y, args, options, state, tags)
        before = jnp.sum(state.f_info.residual ** 2)
        after = jnp.sum(new.f_info.residual ** 2)
        accepted = new.num_accepted_steps > state.num_accepted_steps
        stall = (accepted & (state.num_accepted_steps > 0)
                 & (before - after <= self.loss_rtol * after))
        return y_new, eqx.tree_at(lambda s: s.terminate, new, new.terminate | stall), aux


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


class LossRecording(optx.AbstractSearch):
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
    evaluation, :class:`LossRecording`) all failed to lower the best loss before them by
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
            self.search = LossRecording(self.search, history)

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


def make_solver(name: str, rtol: float, atol: float, sigma_tol: float, history: int):
    """The optimistix solver, with two stopping rules (either one stops it):

    - the Cauchy test (both the step in θ and the change of the residuals below
      ``atol + rtol |·|``), with the RMS norm, not optimistix's default max norm: the residuals
      carry the ODE solver's own noise, which a max over ~2000 points meets only by chance
      (benchmarks/README.md, "Moved from module docstrings (#52)");
    - the statistical test (`sigma_tol` > 0): the Gauss–Newton step from the last accepted
      point is below `sigma_tol` standard errors (:func:`gauss_newton_step_in_sigma`): going
      on cannot move the estimate by a meaningful fraction of its uncertainty. Without it, a
      fit near its optimum spends steps chasing the ODE solver's noise in the residuals;
    - the stall test (with `sigma_tol` > 0, :func:`_noise_stopping`): the step is within
      `_STALL_SIGMA` standard errors and the last `_STALL_EVALUATIONS` evaluations did not
      lower the loss by ½ (`sigma_tol` s)². Where the ODE solver's noise in the loss exceeds
      that amount, the statistical test is met only by chance.

    What each rule saved, as measured: benchmarks/README.md, "Moved from module docstrings (#52)".

    The loss of the first `history` residual evaluations is kept in the solver's state
    (:class:`LossRecording`, read by :func:`dtwin.identify.solve.outcome`)."""
    if name not in _SOLVER_CLASSES:
        raise SettingsError(f"solver must be one of {SOLVERS}, got {name!r}")
    return _SOLVER_CLASSES[name](rtol=rtol, atol=atol, norm=optx.rms_norm, sigma_tol=sigma_tol,
                                 history=history)

