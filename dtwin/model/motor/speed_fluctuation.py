"""A speed fluctuation of the drive: the rotor end of the input shaft oscillates about its speed.

A speed loop that cannot hold the set point against a fluctuating load (a PI controller's
speed dip), a motor's own speed ripple or a belt's slip turns the rotor at
``omega_ref + d_omega(t)`` with ``d_omega = a_cos cos(2 pi f t) + a_sin sin(2 pi f t)`` (rad/s
at the rotor). The gear set sees it through the shaft that joins rotor and sun: the rotor's
angle moves by the integral ``d_theta = (a_cos sin(2 pi f t) - a_sin cos(2 pi f t)) / (2 pi f)``
(zero mean), and the shaft passes on the torque ``k_shaft d_theta + c_shaft d_omega`` (N·m), the
torque it would transmit with the rotor displaced by ``d_theta`` at ``d_omega``. This part
applies that torque at the sun; with an ideal speed source it is exactly the source following
the fluctuating set point, and the drive's own states are untouched (so a motor under speed
control keeps its controller and the fluctuation is superposed on what it does).

Below the shaft-and-gear-set torsional modes the sun, and with it the carrier and every mesh
phase, follows the rotor's angle: the mesh lines are *frequency*-modulated. The sidebands
``m f_m ± f`` grow with the harmonic m (phase deviation ``m z_ring d_theta_c``), unlike those
of a load fluctuation that only modulates the mesh force's amplitude; the two together are what
a speed-controlled drive under a fluctuating load produces.

Both amplitudes 0 give exactly no torque. Without a drive in the twin there is no shaft to
carry the fluctuation and the part does nothing.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ...errors import SpecError
from ..coords import Coords
from ..parts.base import AbstractPart
from .drive import DrivePart
from .shaft import concrete_float


def _f(x: ArrayLike) -> Float[Array, ""]:
    return jnp.asarray(x, dtype=jnp.float64)


class SpeedFluctuation(AbstractPart):
    """Rotor speed fluctuation ``a_cos cos(2 pi f t) + a_sin sin(2 pi f t)`` (rad/s) at
    `frequency` f (Hz > 0), passed to the sun through the drive's shaft (module docstring)."""

    a_cos: Float[Array, ""]
    a_sin: Float[Array, ""]
    frequency: Float[Array, ""]

    def __init__(self, a_cos: ArrayLike, a_sin: ArrayLike, frequency: ArrayLike):
        self.a_cos = _f(a_cos)
        self.a_sin = _f(a_sin)
        self.frequency = _f(frequency)

    def __check_init__(self):
        f = concrete_float(self.frequency)
        if f is not None and not f > 0.0:
            raise SpecError([("speed_fluctuation.frequency", f"must be > 0 Hz, got {f}")])

    def rotor_motion(self, t: Float[Array, ""]) -> tuple[Float[Array, ""], Float[Array, ""]]:
        """``(d_theta, d_omega)``: the rotor's extra angle (rad) and speed (rad/s) at `t` (s)."""
        w = 2.0 * math.pi * self.frequency
        c, s = jnp.cos(w * t), jnp.sin(w * t)
        return (self.a_cos * s - self.a_sin * c) / w, self.a_cos * c + self.a_sin * s

    def forces(self, twin, t, q, qdot, aux, mesh):
        drives = twin.find(DrivePart)
        d_theta, d_omega = self.rotor_motion(t)
        if drives:
            shaft = getattr(drives[0].drive, "shaft", None)
            if shaft is None:
                raise ValueError(f"SpeedFluctuation needs a drive with a `shaft` (k_shaft, "
                                 f"c_shaft); {type(drives[0].drive).__name__} has none")
            torque = shaft.torque(d_theta, d_omega, 0.0, 0.0)  # rotor displaced, sun at rest
        else:
            torque = 0.0 * d_theta
        f = Coords.zeros(twin.n_planets).set(theta_s=torque)
        return f, jnp.zeros(0), {"torque_speed_fluctuation": torque}
