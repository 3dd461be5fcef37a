"""Drive and load as parts of the twin (adapters around `AbstractDrive` / `AbstractLoad`)."""

from __future__ import annotations

import jax.numpy as jnp

from ..coords import Coords
from ..parts.base import AbstractPart
from .drive_base import AbstractDrive, AbstractLoad


class DrivePart(AbstractPart):
    """The drive (motor or speed source, with its shaft) applying torque to the sun."""

    drive: AbstractDrive

    @property
    def aux_size(self) -> int:
        return self.drive.aux_size

    def aux_init(self, twin, omega_sun, torque_sun=None):
        if torque_sun is None:
            return jnp.asarray(self.drive.aux_init(omega_sun)).reshape(self.aux_size)
        return jnp.asarray(self.drive.aux_steady(omega_sun, torque_sun)).reshape(self.aux_size)

    def forces(self, twin, t, q, qdot, aux, mesh):
        torque, aux_dot = self.drive.shaft_torque(t, aux, q.theta_s, qdot.theta_s)
        f = Coords.zeros(twin.n_planets).set(theta_s=torque)
        outputs = self.drive.outputs(t, aux, q.theta_s, qdot.theta_s)
        outputs = dict(outputs)
        outputs["torque_shaft"] = torque
        outputs["power_shaft"] = torque * qdot.theta_s
        return f, aux_dot, outputs


class LoadPart(AbstractPart):
    """The load torque on the carrier (opposing its rotation when positive)."""

    load: AbstractLoad

    def forces(self, twin, t, q, qdot, aux, mesh):
        tl = self.load.torque(t, q.theta_c, qdot.theta_c)
        f = Coords.zeros(twin.n_planets).set(theta_c=-tl)
        return f, jnp.zeros(0), {"torque_load": tl, "power_load": tl * qdot.theta_c}
