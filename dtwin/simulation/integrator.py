"""Tsit5 with its stages written out: the same method as `diffrax.Tsit5`, cheaper per step on CPU.

`diffrax.Tsit5` runs its seven stages in a loop (`equinox.internal.while_loop`) so that one
implementation serves every Runge–Kutta tableau, explicit or implicit. On a CPU the twin's
right-hand side is small (18 degrees of freedom), so a step's cost is the number of separate
operations XLA dispatches, not the arithmetic, and each pass of that stage loop adds its own
bookkeeping (stage index, buffers, the loop's condition). `UnrolledTsit5` writes the stages out
one after the other, so XLA fuses a stage's combination of earlier stages with the next
right-hand side evaluation. Everything else is diffrax's: the step-size controller, the saving
at `ts` through Tsit5's own 5th-order interpolation, the adjoints, the error handling.

The tableau is diffrax's (`Tsitouras 2011`): stages

    k_i = h f(t0 + c_i h, y0 + Σ_{j<i} a_ij k_j),   i = 0…6,

with `y1 = y0 + Σ b_j k_j` (= the input of stage 6, so `f(y1)` is stage 6: first same as last),
and the error estimate `Σ (b_j − b̂_j) k_j`. `tests/test_integrator.py` checks that it takes the
same steps and returns the same solution as `diffrax.Tsit5` to rounding.

It handles an `ODETerm` on a single array state (the twin's scaled state), the only use here.
"""

from __future__ import annotations

import diffrax
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np
from diffrax._solver.tsit5 import _tsit5_tableau

__all__ = ["UnrolledTsit5"]

assert _tsit5_tableau.ssal and _tsit5_tableau.fsal

_A = tuple(np.asarray(a, dtype=np.float64) for a in _tsit5_tableau.a_lower)
_E = np.asarray(_tsit5_tableau.b_error, dtype=np.float64)
_C = np.asarray(_tsit5_tableau.c, dtype=np.float64)


def _combine(y0, coeffs, ks):
    """y0 + Σ_j coeffs[j] ks[j], skipping zero coefficients (compile-time constants)."""
    out = y0
    for c, k in zip(coeffs, ks, strict=True):
        if c != 0.0:
            out = out + float(c) * k
    return out


class UnrolledTsit5(diffrax.Tsit5):
    """Tsitouras' 5(4) method with the stage loop unrolled (see the module docstring).

    Same tableau, error estimate, interpolation and first-same-as-last reuse as
    `diffrax.Tsit5`; a drop-in replacement for an `ODETerm` on an array state.
    """

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        first_step, f0 = solver_state
        control = terms.contr(t0, t1)
        h = t1 - t0
        # f(t0, y0) is the previous step's last stage, except on the first step or after a jump
        # (the predicate is un-batched, so under `vmap` the evaluation is skipped when no batch
        # member needs it).
        redo = first_step | made_jump
        f0 = jax.lax.cond(eqxi.unvmap_any(redo),
                          lambda: jnp.where(redo, terms.vf(t0, y0, args), f0),
                          lambda: f0)
        ks = [terms.prod(f0, control)]
        fi, yi = f0, y0
        for i, a in enumerate(_A):
            yi = _combine(y0, a, ks)
            fi = terms.vf(t0 + float(_C[i]) * h, yi, args)
            ks.append(terms.prod(fi, control))
        y1 = yi  # the last stage's input: its a-row is b (ssal), and f(y1) = fi (fsal)
        y_error = _combine(jnp.zeros_like(y0), _E, ks)
        dense_info = dict(y0=y0, y1=y1, k=jnp.stack(ks))
        return y1, y_error, dense_info, (jnp.array(False), fi), diffrax.RESULTS.successful
