"""Transfer paths: how the gear set's motion reaches an accelerometer on the housing.

A transfer path is a part whose `acceleration(...)` gives the acceleration (m/s²) at the
sensor, along the sensor's direction, in the fixed frame. Several transfer paths add up. The
default `PlanetPassTransferPath` (McFadden & Smith 1985) sees

- the ring's translational acceleration, converted from the carrier frame to the fixed frame
  (``R(theta_c) [r'' + 2 W J r' - W^2 r + W' J r]``, ``W = theta_c'``, ``J`` = rotation by 90°),
  projected on the sensor direction; and
- each planet's ring-mesh contact force ``F_rp_i`` (N) divided by the ring mass and multiplied
  by `force_weight` (a force → acceleration scale; a spec's ``[sensor] housing_mass`` ``M``
  sets ``force_weight = m_ring / M``, so the force reads ``F / M``: the housing, gear set
  included, moving as one body above its mounts), weighted by a window of the planet's angle
  to the sensor,
  ``w(phi) = ((1 + cos phi) / 2) ** window_exponent``, ``phi = theta_c + psi_i - sensor_angle``:
  1 when the planet passes under the sensor, 0 on the far side. ``window_exponent`` controls
  the window width (1: raised cosine; larger: narrower). A calibrated twin gives the window's
  *shape* instead, as a cosine series ``w(phi) = sum_k c_k cos(k phi)``, k = 0 … K-1
  (`window_harmonics`; :func:`window_cosine_coefficients` gives the series of the exponent
  window): the signal is linear in ``c_k``, so a fit can solve for them without re-running the
  ODE. An accelerometer on a housing does not
  see the quasi-static part of a force that travels past it (the static mesh load carried round
  by the carrier), only its dynamic part: the windowed force goes through a high-pass
  ``1 - L(s)``, ``L`` a second-order Butterworth low-pass at `highpass_hz` (a spec's ``[sensor]
  mount_hz``, default 50 Hz, below the mesh frequency), whose two states are the part's own.
  ``(1 - L(s)) / M`` is the acceleration of a mass ``M`` on mounts of stiffness
  ``M (2 pi highpass_hz)²`` (damping ratio 1/√2) driven by the force: above the mounting
  resonance the mass decides (``F / M``), below it the mounts' stiffness (``F ω² / k``), so a
  static planet load carried round at the planet-pass frequency reaches the sensor as a
  deflection of the mounts, not as the housing's free acceleration. A run therefore needs a
  short transient (a few /`highpass_hz`) discarded.

The sensor direction is the unit vector at `direction_angle` in the fixed frame (default
``pi/2``: vertical, +y up), the sensor itself at `sensor_angle` (default ``pi/2``, on top).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..motor.shaft import concrete_float
from .base import AbstractPart


def _rot(theta, v):
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.stack([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _perp(v):
    return jnp.stack([-v[1], v[0]])


def ring_acceleration_fixed(q, qdot, qddot):
    """Acceleration of the ring centre in the fixed frame (m/s²) from carrier-frame coordinates."""
    w, wd = qdot.theta_c, qddot.theta_c
    r, rd, rdd = q.ring_xy, qdot.ring_xy, qddot.ring_xy
    return _rot(q.theta_c, rdd + 2.0 * w * _perp(rd) - w**2 * r + wd * _perp(r))


def ring_velocity_fixed(q, qdot):
    """Velocity of the ring centre in the fixed frame (m/s)."""
    return _rot(q.theta_c, qdot.ring_xy + qdot.theta_c * _perp(q.ring_xy))


def window_cosine_coefficients(exponent: float, n_terms: int) -> np.ndarray:
    """Cosine-series coefficients ``c_0 … c_{K-1}`` of the window ``((1 + cos phi)/2)^p``.

    Exact for an integer exponent ``p < K`` (the window is then a trigonometric polynomial of
    degree p); otherwise the series truncated at K terms (least squares over a period).
    """
    n = 512
    phi = 2.0 * np.pi * np.arange(n) / n
    w = (0.5 * (1.0 + np.cos(phi))) ** float(exponent)
    c = np.fft.rfft(w).real / n
    c[1:] *= 2.0
    return c[:n_terms].copy()


class AbstractTransferPath(AbstractPart):
    """A path from the gear set to the sensor; `acceleration` in m/s² along the sensor axis.

    `aux` are the path's own states (filters, housing modes), as returned by its `forces`.
    """

    @abc.abstractmethod
    def acceleration(self, twin, t, q, qdot, qddot, mesh, aux) -> Float[Array, ""]: ...

    @property
    def output_only(self) -> bool:
        """Whether the path acts on the sensor alone: no force on the gear set, and its own
        states (if any) a linear time-invariant filter of one scalar :meth:`source` of the gear
        set's motion, ``aux = R(i omega) source`` (:meth:`aux_response`), entering
        :meth:`acceleration` linearly. Such states can be computed after the gear set's
        solve (`dtwin.simulate`'s periodic steady state does). True for a path without states."""
        return self.aux_size == 0

    def source(self, twin, q, mesh) -> Float[Array, ""]:
        """The scalar input (m/s²) of the path's states at the configuration `q` and mesh state
        `mesh` (only for an :attr:`output_only` path with states)."""
        raise NotImplementedError(f"{type(self).__name__} has no source")

    def aux_response(self, omega) -> Array:
        """Frequency response of each of the path's states to :meth:`source` at angular
        frequencies `omega` (rad/s): complex, shape ``omega.shape + (aux_size,)``."""
        raise NotImplementedError(f"{type(self).__name__} has no aux_response")

    def aux_decay_time(self) -> float | None:
        """Slowest time constant (s) of the path's states, ``1 / min |Re(pole)|``; None where a
        parameter is traced (its value unknown here)."""
        return None


def second_order_decay_time(omega0, zeta) -> float | None:
    """``1 / min |Re(pole)|`` (s) of ``s² + 2 zeta omega0 s + omega0²``; None for tracers."""
    w, z = concrete_float(omega0), concrete_float(zeta)
    if w is None or z is None or w <= 0.0 or z <= 0.0:
        return None
    slow = w * (z - np.sqrt(z * z - 1.0)) if z > 1.0 else w * z
    return 1.0 / slow


def second_order_response(omega, omega0, zeta):
    """``[H, i omega H]`` with ``H = omega0² / ((i omega)² + 2 zeta omega0 i omega + omega0²)``:
    the response of a second-order low-pass's output and its rate, shape ``omega.shape + (2,)``.
    Complex numbers built from real parts (JAX's strict dtype promotion)."""
    omega = jnp.asarray(omega, dtype=jnp.float64)
    re = omega0**2 - omega**2
    im = 2.0 * zeta * omega0 * omega
    den = re * re + im * im
    h = jax.lax.complex(omega0**2 * re / den, -omega0**2 * im / den)
    dh = jax.lax.complex(-omega * jnp.imag(h), omega * jnp.real(h))
    return jnp.stack([h, dh], axis=-1)


class PlanetPassTransferPath(AbstractTransferPath):
    """Ring motion plus planet mesh forces seen through a planet-angle window (module docs)."""

    sensor_angle: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(jnp.pi / 2))
    direction_angle: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(jnp.pi / 2))
    window_exponent: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(4.0))
    ring_weight: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(1.0))
    force_weight: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(1.0))
    highpass_hz: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.asarray(50.0))
    window_harmonics: Float[Array, " K"] | None = None

    @property
    def aux_size(self) -> int:
        return 2

    def window(self, twin, q) -> Float[Array, " N"]:
        phi = q.theta_c + twin.lp.planet_angles - self.sensor_angle
        if self.window_harmonics is not None:
            k = jnp.arange(self.window_harmonics.shape[0], dtype=jnp.float64)
            return jnp.cos(phi[:, None] * k) @ self.window_harmonics
        return (0.5 * (1.0 + jnp.cos(phi))) ** self.window_exponent

    def windowed_force(self, twin, q, mesh) -> Float[Array, ""]:
        """``sum_i w_i F_rp_i / m_ring`` (m/s²) before the high-pass."""
        return jnp.sum(self.window(twin, q) * mesh.force_rp) / twin.lp.m_ring

    @property
    def output_only(self) -> bool:
        return True

    def source(self, twin, q, mesh):
        return self.windowed_force(twin, q, mesh)

    def aux_response(self, omega):
        # the Butterworth low-pass L(s) = w² / (s² + sqrt(2) w s + w²) and its rate
        return second_order_response(omega, 2.0 * jnp.pi * self.highpass_hz, np.sqrt(0.5))

    def aux_decay_time(self):
        return second_order_decay_time(2.0 * np.pi * self.highpass_hz, np.sqrt(0.5))

    def aux_from_state(self, twin, t, q, qdot, mesh):
        """Filter states of a steady run: the low-pass holds the windowed force."""
        return jnp.stack([self.windowed_force(twin, q, mesh), jnp.zeros(())])

    def forces(self, twin, t, q, qdot, aux, mesh):
        w = 2.0 * jnp.pi * self.highpass_hz
        s = self.windowed_force(twin, q, mesh)
        z1, z2 = aux[0], aux[1]
        aux_dot = jnp.stack([z2, w**2 * (s - z1) - jnp.sqrt(2.0) * w * z2])
        return None, aux_dot, {}

    def acceleration(self, twin, t, q, qdot, qddot, mesh, aux):
        d = jnp.stack([jnp.cos(self.direction_angle), jnp.sin(self.direction_angle)])
        a_ring = ring_acceleration_fixed(q, qdot, qddot) @ d
        a_force = self.windowed_force(twin, q, mesh) - aux[0]
        return self.ring_weight * a_ring + self.force_weight * a_force
