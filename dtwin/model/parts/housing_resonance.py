"""A housing resonance in the transfer path: the sensor sees the mesh forces through a mode.

The planet-pass transfer path (:mod:`dtwin.model.parts.transfer_path`) is flat in frequency: the
windowed ring-mesh force per ring mass, ``s(t) = sum_i w_i F_rp_i / m_ring``, reaches the sensor
unchanged. A housing mode at `f_res` with damping ratio `zeta` filters it,
``H(s) = w0^2 / (s^2 + 2 zeta w0 s + w0^2)`` (w0 = 2 pi f_res). This part adds

    a_sensor += gain * (x − s),      x'' + 2 zeta w0 x' + w0^2 x = w0^2 s

so that with `gain` = 1 a flat path (force weight 1) becomes the resonant one, ``H s``; `gain`
= 0 adds exactly nothing, and the output is linear in `gain`. ``H − 1`` vanishes at low
frequency, so the quasi-static load carried round by the carrier does not leak in. Lines near
`f_res` grow by ``|1 + gain (H − 1)|`` (up to ``1 / (2 zeta)`` at resonance); no new lines
appear. The resonator's two states (x, x') are the part's own and start in steady state.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .transfer_path import (
    AbstractTransferPath,
    second_order_decay_time,
    second_order_response,
)

__all__ = ["HousingResonance", "resonance_gain"]


def resonance_gain(f, f_res: float, zeta: float, gain: float = 1.0) -> np.ndarray:
    """Path gain ``|1 + gain (H(i 2 pi f) − 1)|`` of :class:`HousingResonance` at `f` (Hz)
    (numpy)."""
    s = 1j * np.asarray(f, dtype=float) / f_res
    h = 1.0 / (s * s + 2.0 * zeta * s + 1.0)
    return np.abs(1.0 + gain * (h - 1.0))


class HousingResonance(AbstractTransferPath):
    """A housing mode in the transfer path (module docstring).

    `gain` (1): share of the force path that passes through the mode; `f_res` (Hz) and `zeta`
    (1): the mode; `sensor_angle` (rad) and `window_exponent`: the planet window of the force
    path it filters (as :class:`dtwin.model.parts.transfer_path.PlanetPassTransferPath`).
    """

    gain: Float[Array, ""]
    f_res: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(1500.0))
    zeta: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(0.05))
    sensor_angle: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(jnp.pi / 2))
    window_exponent: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(4.0))

    @property
    def aux_size(self) -> int:
        return 2

    def _source(self, twin, q, mesh):
        phi = q.theta_c + twin.lp.planet_angles - self.sensor_angle
        w = (0.5 * (1.0 + jnp.cos(phi))) ** self.window_exponent
        return jnp.sum(w * mesh.force_rp) / twin.lp.m_ring

    @property
    def output_only(self) -> bool:
        return True

    def source(self, twin, q, mesh):
        return self._source(twin, q, mesh)

    def aux_response(self, omega):
        return second_order_response(omega, 2.0 * jnp.pi * self.f_res, self.zeta)

    def aux_decay_time(self):
        return second_order_decay_time(2.0 * np.pi * self.f_res, self.zeta)

    def aux_from_state(self, twin, t, q, qdot, mesh):
        """Steady start: the mode follows the quasi-static force."""
        return jnp.stack([self._source(twin, q, mesh), jnp.zeros(())])

    def forces(self, twin, t, q, qdot, aux, mesh):
        w0 = 2.0 * jnp.pi * self.f_res
        s = self._source(twin, q, mesh)
        x, v = aux[0], aux[1]
        aux_dot = jnp.stack([v, w0**2 * (s - x) - 2.0 * self.zeta * w0 * v])
        return None, aux_dot, {}

    def acceleration(self, twin, t, q, qdot, qddot, mesh, aux):
        return self.gain * (aux[0] - self._source(twin, q, mesh))
