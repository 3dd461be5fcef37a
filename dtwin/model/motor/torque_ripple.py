"""Motor torque ripple: a torque on the sun at a harmonic of the motor's electrical frequency.

``T(theta_s) = a_cos cos(h p theta_s) + a_sin sin(h p theta_s)`` (N·m), `p` the motor's pole
pairs and `h` the harmonic (cogging and the spatial harmonics of a PMSM give h = 6, 12 …;
current-sensor offsets h = 1, gain mismatch h = 2). The electrical angle is ``p theta_s``: the
motor shaft turns with the sun. The torque is applied at the sun (the gear end of the input
shaft); with an ideal speed source the rotor end cannot respond, so the ripple must act there.
Both amplitudes 0 give exactly no torque.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..coords import Coords
from ..parts.base import AbstractPart


class TorqueRipple(AbstractPart):
    """Torque ripple on the sun (module docstring): `a_cos`, `a_sin` (N·m), static
    `pole_pairs` and `harmonic`."""

    a_cos: Float[Array, ""]
    a_sin: Float[Array, ""]
    pole_pairs: int = eqx.field(static=True, default=4)
    harmonic: int = eqx.field(static=True, default=6)

    def __check_init__(self):
        if self.pole_pairs < 1 or self.harmonic < 1:
            raise ValueError("TorqueRipple: pole_pairs and harmonic must be integers >= 1, got "
                             f"{self.pole_pairs}, {self.harmonic}")

    def forces(self, twin, t, q, qdot, aux, mesh):
        ang = self.harmonic * self.pole_pairs * q.theta_s
        torque = self.a_cos * jnp.cos(ang) + self.a_sin * jnp.sin(ang)
        f = Coords.zeros(twin.n_planets).set(theta_s=torque)
        return f, jnp.zeros(0), {"torque_ripple": torque}
