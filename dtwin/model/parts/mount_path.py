"""The housing on its mounts: a low-frequency line reaching the sensor by a path of its own.

A gearbox housing sits on mounts (feet, rubber elements, a bedplate). A load torque or a force
that fluctuates at a low frequency `f` — below the planet-pass frequency, the lowest line a
healthy record holds — rocks the housing on them, and an accelerometer on the housing sees that
rigid-body motion. How strongly depends on the mounts' stiffness and the housing's mass, which
nobody publishes and no healthy record measures (below its lowest line there is nothing to
calibrate against): far below the mounting modes the acceleration falls as ``f²`` (the
force-over-compliance law of :class:`dtwin.model.parts.transfer_path.PlanetPassTransferPath`'s
high-pass), near them it rises. At one frequency the path is a gain and a phase, so this part
adds to the sensor's acceleration

    a(t) = a_cos cos(2 pi f t) + a_sin sin(2 pi f t)        (m/s²)

linear in both amplitudes; both 0 add exactly nothing. It has no states and moves nothing in
the gear set: it is the line at `f` of a fluctuation whose other lines (its mesh sidebands)
the twin makes through the gears.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .transfer_path import AbstractTransferPath

__all__ = ["MountPath"]


class MountPath(AbstractTransferPath):
    """Sensor acceleration at `f` (Hz) through the housing's mounts (module docstring).

    `a_cos`, `a_sin` (m/s²): the line's cosine and sine amplitudes at the sensor, time in s from
    the twin's zero.
    """

    a_cos: Float[Array, ""]
    a_sin: Float[Array, ""]
    f: float = eqx.field(static=True, default=1.0)

    def acceleration(self, twin, t, q, qdot, qddot, mesh, aux):
        w = 2.0 * jnp.pi * self.f
        return self.a_cos * jnp.cos(w * t) + self.a_sin * jnp.sin(w * t)
