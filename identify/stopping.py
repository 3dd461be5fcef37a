"""A stopping rule for Levenberg–Marquardt fits whose loss stops falling before their step does.

Optimistix's Levenberg–Marquardt stops on the Cauchy test: both the step in the parameters and
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
import jax.numpy as jnp
import optimistix as optx

__all__ = ["StallStopping"]


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
