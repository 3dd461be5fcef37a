"""The static problem of a steady run: the mean-stiffness gear set under its load torque.

:func:`static_balance` gives the linear stiffness and static forces over the integration
coordinates with the carrier angle held (mean mesh stiffness, linear contact, the parts'
springs, the load torque at the carrier speed and the planets' centripetal pre-load). The
steady start of a simulation (:func:`dtwin.simulation.simulate.initial_state`) solves it, and so does the
load-sharing imperfection that sets planet clearances for stated shares
(:func:`dtwin.model.parts.imperfections.load_share_offsets`). Forces in N and N·m, speeds in rad/s.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .coords import Coords
from .motor.drive import LoadPart

if TYPE_CHECKING:
    from .twin import Twin

__all__ = ["static_balance", "static_forces"]


def static_forces(twin: Twin, omega_c):
    """Generalised static forces: load torque on the carrier and the balancing sun torque."""
    tl = jnp.zeros(())
    for p in twin.find(LoadPart):
        tl = tl + p.load.torque(jnp.zeros(()), jnp.zeros(()), omega_c)
    rs, _ = twin.kinematic_ratios
    f = Coords.zeros(twin.n_planets).set(theta_c=-tl, theta_s=tl / rs)
    # centripetal force on the planets (bearing pre-load)
    f = f + twin.frame_forces(Coords.zeros(twin.n_planets), Coords.zeros(twin.n_planets).set(theta_c=omega_c))
    return f, tl / rs


def static_balance(twin: Twin, omega_c):
    """The static problem of a steady run: mean mesh stiffness, linear contact, the parts'
    springs, the carrier angle held and the load torque at carrier speed `omega_c` (rad/s).

    **Returns:** `(A, keep, K, F, torque_sun)`: the kinematic map, the integration coordinates
    other than the carrier angle, the stiffness and static forces over them, and the sun torque
    that balances the load."""
    A, K, F, torque_sun = _stiffness_and_forces(twin, jnp.asarray(omega_c, dtype=jnp.float64))
    ic = twin._index("theta_c")
    keep = np.array([i for i in range(twin.n_dof) if i != ic])
    return A, keep, K[np.ix_(keep, keep)], F[keep], torque_sun


@eqx.filter_jit
def _stiffness_and_forces(twin: Twin, omega_c):
    """The kinematic map, stiffness and static forces over all integration coordinates, and the
    sun torque: one compiled program (a twin is built outside any `jit`, and this Jacobian's
    few hundred operations, run one by one, cost seconds of compilation in every new process;
    compiled together they are one entry of the persistent compilation cache)."""
    A = jnp.asarray(twin.kinematic_map())
    K = A.T @ twin.linear_stiffness(modal=False) @ A
    f, torque_sun = static_forces(twin, omega_c)
    return A, K, A.T @ twin.pack(f), torque_sun
