"""Load torques on the carrier (output shaft).

Positive torque opposes the carrier's CCW rotation (docs/conventions.md). A bench's brake
(magnetic-powder or eddy-current) cannot drive the gearbox backwards, so by default a load
*engages* with the carrier speed: the torque is multiplied by `tanh(omega_c / engage_speed)`,
which is 1 to machine precision at running speed (1 - 2e-16 at 18 engage speeds) and 0 at
standstill, so a start from standstill does not spin the gearbox backwards while the motor's
torque builds up. Set `engage_speed = 0` for an active load torque that acts at any speed.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ...errors import SpecError
from .drive_base import AbstractLoad
from .shaft import concrete_float

#: Default engagement speed of a passive brake (rad/s at the carrier).
ENGAGE_SPEED_DEFAULT = 0.5


def _f(x: ArrayLike) -> Float[Array, ""]:
    return jnp.asarray(x, dtype=jnp.float64)


def _engagement(omega_c: Float[Array, ""], engage_speed: Float[Array, ""]) -> Float[Array, ""]:
    """`tanh(omega_c / engage_speed)` for `engage_speed > 0`, 1 for `engage_speed = 0`."""
    safe = jnp.where(engage_speed > 0.0, engage_speed, 1.0)
    return jnp.where(engage_speed > 0.0, jnp.tanh(omega_c / safe), 1.0)


def _check_engage(engage_speed: Float[Array, ""]) -> None:
    e = concrete_float(engage_speed)
    if e is not None and not e >= 0.0:
        raise SpecError([("operating.engage_speed", f"must be >= 0 rad/s, got {e}")])


class ConstantLoad(AbstractLoad):
    """Constant load torque `T = torque tanh(omega_c / engage_speed)` (N·m) on the carrier.

    **Fields:** `torque` (N·m, positive opposes CCW rotation), `engage_speed` (rad/s at the
    carrier, default 0.5; 0 for a torque that also acts at standstill).
    """

    torque_value: Float[Array, ""]
    engage_speed: Float[Array, ""]

    def __init__(self, torque: ArrayLike, engage_speed: ArrayLike = ENGAGE_SPEED_DEFAULT):
        self.torque_value = _f(torque)
        self.engage_speed = _f(engage_speed)

    def __check_init__(self):
        _check_engage(self.engage_speed)

    def torque(self, t, theta_carrier, omega_carrier):
        """Load torque (N·m) at time `t` (s), carrier angle (rad) and speed (rad/s)."""
        return self.torque_value * _engagement(omega_carrier, self.engage_speed) + 0.0 * t


class FluctuatingLoad(AbstractLoad):
    """Load torque `(mean + amplitude sin(2 pi frequency t + phase)) tanh(omega_c / engage_speed)`.

    **Fields:** `mean`, `amplitude` (N·m), `frequency` (Hz), `phase` (rad), `engage_speed`
    (rad/s at the carrier, 0 for an active load). A fluctuation at `f_x` modulates the motor
    torque and shows in the phase-current spectrum as sidebands `f_e ± f_x` (motor-current
    signature analysis).
    """

    mean: Float[Array, ""]
    amplitude: Float[Array, ""]
    frequency: Float[Array, ""]
    phase: Float[Array, ""]
    engage_speed: Float[Array, ""]

    def __init__(
        self,
        mean: ArrayLike,
        amplitude: ArrayLike,
        frequency: ArrayLike,
        phase: ArrayLike = 0.0,
        engage_speed: ArrayLike = ENGAGE_SPEED_DEFAULT,
    ):
        self.mean = _f(mean)
        self.amplitude = _f(amplitude)
        self.frequency = _f(frequency)
        self.phase = _f(phase)
        self.engage_speed = _f(engage_speed)

    def __check_init__(self):
        _check_engage(self.engage_speed)
        f = concrete_float(self.frequency)
        if f is not None and not f >= 0.0:
            raise SpecError([("operating.load_frequency", f"must be >= 0 Hz, got {f}")])

    def torque(self, t, theta_carrier, omega_carrier):
        """Load torque (N·m) at time `t` (s), carrier angle (rad) and speed (rad/s)."""
        fluct = self.amplitude * jnp.sin(2.0 * math.pi * self.frequency * t + self.phase)
        return (self.mean + fluct) * _engagement(omega_carrier, self.engage_speed)
