"""Local tooth faults as parts: the stiffness a faulty tooth removes while it is in mesh.

The physics (severity → stiffness, contact windows) lives in `dtwin/model/faults.py`; this part only
plugs a fault into the twin's meshes.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..faults import AbstractFault
from .base import AbstractPart, Modulation


class LocalFault(AbstractPart):
    """A local fault (`MissingTooth`, `Pitting`, `RootCrack`, …) acting on the meshes."""

    fault: AbstractFault

    def modulation(self, twin, t, q, qdot):
        dk_sp, dk_rp = self.fault.stiffness_loss(twin.lp, q.theta_s, q.theta_c, q.theta_r, q.theta_p)
        z = jnp.zeros(twin.n_planets)
        return Modulation(dk_sp, dk_rp, z, z, z, z)
