"""Speed references and the ideal speed source (the paper's "traditional" model).

`SpeedProfile` is the speed set point of every drive as a function of time (rad/s at the motor
shaft): a step (the paper's Simulink STEP, start from standstill), a linear ramp, or a constant.
`IdealSpeedSource` makes the rotor end of the shaft follow the profile exactly, whatever the
torque: the sun is then driven through the same flexible shaft as in the motor-coupled twin, so
the two models differ only in what turns the rotor.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ...errors import SpecError
from .drive_base import AbstractDrive
from .shaft import Shaft, concrete_float

_KINDS = ("step", "ramp", "constant")


def rpm_to_rad_s(rpm: float) -> float:
    """Speed in rpm to rad/s, `omega = 2 pi rpm / 60`."""
    return 2.0 * math.pi * float(rpm) / 60.0


class SpeedProfile(eqx.Module):
    """Speed set point `omega_ref(t)` (rad/s) at the motor shaft.

    - `kind="step"`:     `omega_ref = initial` for `t < t_start`, `final` afterwards.
    - `kind="ramp"`:     `initial + (final - initial) clip((t - t_start) / ramp_time, 0, 1)`.
    - `kind="constant"`: `final` at all times.

    **Fields:** `kind` (static), `initial`, `final` (rad/s), `t_start` (s), `ramp_time` (s, > 0
    for a ramp). Build with :meth:`step`, :meth:`ramp` or :meth:`constant`.
    """

    kind: str = eqx.field(static=True)
    initial: Float[Array, ""]
    final: Float[Array, ""]
    t_start: Float[Array, ""]
    ramp_time: Float[Array, ""]

    def __check_init__(self):
        if self.kind not in _KINDS:
            raise SpecError([("motor.start", f"unknown speed profile {self.kind!r}; use one of {_KINDS}")])
        rt = concrete_float(self.ramp_time)
        if self.kind == "ramp" and rt is not None and not rt > 0.0:
            raise SpecError([("motor.ramp_time", f"a ramp needs ramp_time > 0 s, got {rt}")])

    @classmethod
    def step(cls, speed: ArrayLike, t_start: ArrayLike = 0.0, initial: ArrayLike = 0.0) -> SpeedProfile:
        """Step from `initial` to `speed` (rad/s) at `t_start` (s); at t_start = 0 the reference is
        `speed` from the first instant (start from standstill, the paper's STEP)."""
        return cls("step", _f(initial), _f(speed), _f(t_start), _f(0.0))

    @classmethod
    def ramp(
        cls, speed: ArrayLike, ramp_time: ArrayLike, t_start: ArrayLike = 0.0, initial: ArrayLike = 0.0
    ) -> SpeedProfile:
        """Linear ramp from `initial` to `speed` (rad/s) over `ramp_time` (s) from `t_start` (s)."""
        return cls("ramp", _f(initial), _f(speed), _f(t_start), _f(ramp_time))

    @classmethod
    def constant(cls, speed: ArrayLike) -> SpeedProfile:
        """Constant set point `speed` (rad/s) (a start at speed)."""
        return cls("constant", _f(speed), _f(speed), _f(0.0), _f(0.0))

    def __call__(self, t: Float[Array, ""]) -> Float[Array, ""]:
        """Set point `omega_ref(t)` (rad/s) at time `t` (s)."""
        if self.kind == "constant":
            return self.final + 0.0 * t
        if self.kind == "step":
            return jnp.where(t >= self.t_start, self.final, self.initial)
        frac = jnp.clip((t - self.t_start) / self.ramp_time, 0.0, 1.0)
        return self.initial + (self.final - self.initial) * frac

    def angle(self, t: Float[Array, ""]) -> Float[Array, ""]:
        """Integral of the set point from 0 to `t`, `int_0^t omega_ref dt'` (rad).

        Closed form: piecewise linear (step, constant) or linear + quadratic (ramp); `t_start`
        may be negative (a profile already under way at t = 0).
        """
        return self._antiderivative(t) - self._antiderivative(0.0 * t)

    def _antiderivative(self, t):
        if self.kind == "constant":
            return self.final * t
        if self.kind == "step":
            return self.initial * t + (self.final - self.initial) * jnp.maximum(t - self.t_start, 0.0)
        tau = jnp.clip(t - self.t_start, 0.0, self.ramp_time)
        after = jnp.maximum(t - self.t_start - self.ramp_time, 0.0)
        d = self.final - self.initial
        return self.initial * t + d * tau**2 / (2.0 * self.ramp_time) + d * after

    def jump_times(self) -> list[float]:
        """Times (s) where the set point is not smooth (a step's jump, a ramp's two kinks), to give
        an adaptive solver as `diffrax.ClipStepSizeController(jump_ts=...)`; concrete values only."""
        if self.kind == "constant":
            return []
        t0 = float(self.t_start)
        return [t0] if self.kind == "step" else [t0, t0 + float(self.ramp_time)]


def _f(x: ArrayLike) -> Float[Array, ""]:
    return jnp.asarray(x, dtype=jnp.float64)


class IdealSpeedSource(AbstractDrive):
    """The rotor end of the shaft follows `speed` exactly (the paper's "traditional" model).

    State `aux = [theta_m]` (rad), `d theta_m/dt = omega_ref(t)`. The source supplies whatever
    torque the shaft transmits: `T_shaft = k (theta_m - theta_s) + c (omega_ref - omega_s)`.

    **Fields:** `speed` (`SpeedProfile`), `shaft` (`Shaft`).
    """

    speed: SpeedProfile
    shaft: Shaft

    @property
    def aux_size(self) -> int:
        return 1

    @property
    def aux_names(self) -> tuple[str, ...]:
        """Names of the entries of `aux`."""
        return ("theta_motor",)

    def steady_speed(self, torque_sun: ArrayLike = 0.0) -> Float[Array, ""]:
        """Steady sun speed (rad/s) under a steady shaft torque: the set point at t = 0."""
        return self.speed(_f(0.0)) + 0.0 * _f(torque_sun)

    def aux_init(self, omega_sun: Float[Array, ""], torque_sun: ArrayLike = 0.0) -> Float[Array, " 1"]:
        """State at t = 0 with the sun at angle 0: the shaft twisted by `torque_sun / k_shaft`.

        **Arguments:** `omega_sun` (rad/s, unused: the rotor speed is the set point), `torque_sun`
        steady shaft torque (N·m, 0 for a start from standstill).
        """
        del omega_sun
        return jnp.reshape(self.shaft.twist_for(torque_sun), (1,))

    def shaft_torque(self, t, aux, theta_sun, omega_sun):
        omega_m = self.speed(t)
        torque = self.shaft.torque(aux[0], omega_m, theta_sun, omega_sun)
        return torque, jnp.reshape(omega_m, (1,))

    def outputs(self, t, aux, theta_sun, omega_sun) -> dict[str, Float[Array, ""]]:
        """`omega_motor`, `omega_ref`, `theta_motor`, `torque_em` (= shaft torque, N·m),
        `torque_shaft`, `power_in` (W, `T_shaft omega_ref`), `power_shaft` (to the sun, W),
        `power_copper` = `power_friction` = 0, `power_shaft_damping`, `power_loss`,
        `energy_stored` (shaft strain, J)."""
        omega_m = self.speed(t)
        theta_m = aux[0]
        torque = self.shaft.torque(theta_m, omega_m, theta_sun, omega_sun)
        p_damp = self.shaft.damping_power(omega_m - omega_sun)
        zero = 0.0 * torque
        return {
            "omega_motor": omega_m,
            "omega_ref": omega_m,
            "theta_motor": theta_m,
            "torque_em": torque,
            "torque_shaft": torque,
            "power_in": torque * omega_m,
            "power_shaft": torque * omega_sun,
            "power_copper": zero,
            "power_friction": zero,
            "power_shaft_damping": p_damp,
            "power_loss": p_damp,
            "energy_stored": self.shaft.strain_energy(theta_m - theta_sun),
        }
