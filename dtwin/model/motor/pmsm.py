"""Permanent-magnet synchronous motor (PMSM) under field-oriented control, driving the sun.

The paper's drive (Simulink PMSM block behind a universal bridge, started by a STEP in speed).
Here: the dq model in the rotor frame (amplitude-invariant Park transform, electrical angle
`theta_e = p theta_m`), an averaged inverter (no PWM ripple) and cascaded PI control.

Machine (R_s, L_d, L_q, psi_f, p, J_m, b):

    L_d di_d/dt = v_d - R_s i_d + omega_e L_q i_q
    L_q di_q/dt = v_q - R_s i_q - omega_e (L_d i_d + psi_f)
    T_em        = 1.5 p (psi_f i_q + (L_d - L_q) i_d i_q)
    J_m domega_m/dt = T_em - b omega_m - T_shaft,      omega_e = p omega_m

Control (field orientation, `i_d* = 0`):

    speed PI :  u_w = K_pw e_w + x_w,  e_w = omega_ref(t) - omega_m,  i_q* = sat(u_w; I_max)
    current PI: v_d* = K_pd e_d + x_d - omega_e L_q i_q,  v_q* = K_pq e_q + x_q + omega_e (L_d i_d + psi_f)
    inverter :  v = v* sat(|v*|; V_dc/sqrt 3) / |v*|   (averaged, DC-link voltage limit)

Gains from bandwidths: current loops by pole-zero cancellation, `K_p = L omega_cc`,
`K_i = R_s omega_cc` (closed loop first order at `omega_cc = 2 pi current_bandwidth`); speed loop
on the tuning inertia `J_t = J_m (1 + load_inertia_ratio)`, `K_pw = J_t omega_sc / K_t`,
`K_iw = K_pw omega_sc / 4` with `K_t = 1.5 p psi_f` (closed loop `s² + omega_sc s + omega_sc²/4`:
a critically damped double pole at `-omega_sc / 2`, `omega_sc = 2 pi speed_bandwidth`).

Saturations are smooth (differentiable everywhere): `sat(u; L) = u (1 + (u/L)^n)^(-1/n)`, n = 8,
within 0.05 % of the identity below half the limit. Anti-windup is smooth conditional integration:
each integrator runs at `K_i e sat'(u)`, which freezes it while its output is saturated and makes
`e = 0` an exact equilibrium (so :meth:`PMSM.aux_init` preloads an exact steady state).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ...errors import SpecError
from .drive_base import AbstractDrive
from .shaft import Shaft, concrete_float
from .speed_source import SpeedProfile, rpm_to_rad_s

#: Order n of the smooth saturation `u (1 + (u/L)^n)^(-1/n)` (even).
CLIP_ORDER = 8

_SQRT3 = math.sqrt(3.0)
_TWO_PI_3 = 2.0 * math.pi / 3.0


def soft_clip(u: Float[Array, "*s"], limit: Float[Array, ""]) -> Float[Array, "*s"]:
    """Smooth saturation `u (1 + (u/L)^n)^(-1/n)` (n = `CLIP_ORDER`, even): odd, C-infinity,
    slope 1 at 0, tends to `±L`. Same units as `u` and `limit`."""
    r = (u / limit) ** CLIP_ORDER
    return u * (1.0 + r) ** (-1.0 / CLIP_ORDER)


def soft_clip_slope(u: Float[Array, "*s"], limit: Float[Array, ""]) -> Float[Array, "*s"]:
    """Derivative of :func:`soft_clip`, `(1 + (u/L)^n)^(-1/n - 1)` in (0, 1]."""
    r = (u / limit) ** CLIP_ORDER
    return (1.0 + r) ** (-1.0 / CLIP_ORDER - 1.0)


def soft_clip_inverse(y: Float[Array, "*s"], limit: Float[Array, ""]) -> Float[Array, "*s"]:
    """Inverse of :func:`soft_clip`: `y (1 - (y/L)^n)^(-1/n)` for `|y| < L`."""
    r = (y / limit) ** CLIP_ORDER
    return y * (1.0 - r) ** (-1.0 / CLIP_ORDER)


def inverse_park(
    i_d: Float[Array, ""], i_q: Float[Array, ""], theta_e: Float[Array, ""]
) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
    """Phase quantities from dq (amplitude-invariant): `i_a = i_d cos(th) - i_q sin(th)`,
    `i_b`, `i_c` the same at `th - 2pi/3`, `th + 2pi/3`. Units of the inputs; `theta_e` in rad."""
    a = i_d * jnp.cos(theta_e) - i_q * jnp.sin(theta_e)
    b = i_d * jnp.cos(theta_e - _TWO_PI_3) - i_q * jnp.sin(theta_e - _TWO_PI_3)
    c = i_d * jnp.cos(theta_e + _TWO_PI_3) - i_q * jnp.sin(theta_e + _TWO_PI_3)
    return a, b, c


def _f(x: ArrayLike) -> Float[Array, ""]:
    return jnp.asarray(x, dtype=jnp.float64)


#: Default PMSM parameters: a 4-pole-pair servo motor of ~3.8 kW at 1800 rpm (20 N·m rated,
#: K_t = 1.08 N·m/A, 560 V DC link). See docs/motor.md.
PMSM_DEFAULTS: dict[str, float] = {
    "R_s": 0.45,  # ohm, stator resistance per phase
    "L_d": 4.0e-3,  # H
    "L_q": 4.5e-3,  # H
    "psi_f": 0.18,  # Wb (V·s), magnet flux linkage (peak, per phase)
    "pole_pairs": 4,
    "J_m": 3.0e-3,  # kg·m², rotor inertia
    "friction": 1.0e-3,  # N·m·s/rad, viscous friction of the rotor
    "V_dc": 560.0,  # V, DC-link voltage (400 V mains rectified)
    "current_limit": 40.0,  # A (peak phase current), ~2.2× rated
    "speed_bandwidth": 20.0,  # Hz
    "current_bandwidth": 1000.0,  # Hz
    "load_inertia_ratio": 0.5,  # load inertia (at the motor) / J_m assumed by the speed loop
}


class PMSM(AbstractDrive):
    """PMSM + FOC + averaged inverter + flexible shaft, driving the sun.

    State `aux = [theta_m, omega_m, i_d, i_q, x_w, x_d, x_q]`: rotor angle (rad) and speed
    (rad/s), dq currents (A), speed-PI integrator (A), current-PI integrators (V).

    **Fields** (SI): `speed` (`SpeedProfile`, rad/s), `shaft` (`Shaft`), `R_s` (ohm), `L_d`,
    `L_q` (H), `psi_f` (Wb), `pole_pairs` (static int), `J_m` (kg·m²), `friction` (N·m·s/rad),
    `V_dc` (V), `current_limit` (A peak), `speed_bandwidth`, `current_bandwidth` (Hz),
    `load_inertia_ratio` (1). Defaults: `PMSM_DEFAULTS`.
    """

    speed: SpeedProfile
    shaft: Shaft
    R_s: Float[Array, ""]
    L_d: Float[Array, ""]
    L_q: Float[Array, ""]
    psi_f: Float[Array, ""]
    pole_pairs: int = eqx.field(static=True)
    J_m: Float[Array, ""]
    friction: Float[Array, ""]
    V_dc: Float[Array, ""]
    current_limit: Float[Array, ""]
    speed_bandwidth: Float[Array, ""]
    current_bandwidth: Float[Array, ""]
    load_inertia_ratio: Float[Array, ""]

    def __init__(
        self,
        speed: SpeedProfile | None = None,
        shaft: Shaft | None = None,
        *,
        R_s: ArrayLike = PMSM_DEFAULTS["R_s"],
        L_d: ArrayLike = PMSM_DEFAULTS["L_d"],
        L_q: ArrayLike = PMSM_DEFAULTS["L_q"],
        psi_f: ArrayLike = PMSM_DEFAULTS["psi_f"],
        pole_pairs: int = int(PMSM_DEFAULTS["pole_pairs"]),
        J_m: ArrayLike = PMSM_DEFAULTS["J_m"],
        friction: ArrayLike = PMSM_DEFAULTS["friction"],
        V_dc: ArrayLike = PMSM_DEFAULTS["V_dc"],
        current_limit: ArrayLike = PMSM_DEFAULTS["current_limit"],
        speed_bandwidth: ArrayLike = PMSM_DEFAULTS["speed_bandwidth"],
        current_bandwidth: ArrayLike = PMSM_DEFAULTS["current_bandwidth"],
        load_inertia_ratio: ArrayLike = PMSM_DEFAULTS["load_inertia_ratio"],
    ):
        """Defaults: `PMSM_DEFAULTS`; `speed` defaults to a step to 1800 rpm at t = 0 (the
        paper's STEP), `shaft` to `Shaft()`."""
        self.speed = SpeedProfile.step(rpm_to_rad_s(1800.0)) if speed is None else speed
        self.shaft = Shaft() if shaft is None else shaft
        self.R_s = _f(R_s)
        self.L_d = _f(L_d)
        self.L_q = _f(L_q)
        self.psi_f = _f(psi_f)
        self.pole_pairs = int(pole_pairs)
        self.J_m = _f(J_m)
        self.friction = _f(friction)
        self.V_dc = _f(V_dc)
        self.current_limit = _f(current_limit)
        self.speed_bandwidth = _f(speed_bandwidth)
        self.current_bandwidth = _f(current_bandwidth)
        self.load_inertia_ratio = _f(load_inertia_ratio)

    def __check_init__(self):
        problems = []
        if self.pole_pairs < 1:
            problems.append(("motor.pmsm.pole_pairs", f"must be an integer >= 1, got {self.pole_pairs}"))
        for name in ("R_s", "L_d", "L_q", "psi_f", "J_m", "V_dc", "current_limit",
                     "speed_bandwidth", "current_bandwidth"):
            v = concrete_float(getattr(self, name))
            if v is not None and not v > 0.0:
                problems.append((f"motor.pmsm.{name}", f"must be > 0 (SI units), got {v}"))
        for name in ("friction", "load_inertia_ratio"):
            v = concrete_float(getattr(self, name))
            if v is not None and not v >= 0.0:
                problems.append((f"motor.pmsm.{name}", f"must be >= 0, got {v}"))
        if problems:
            raise SpecError(problems)

    # --- derived quantities -------------------------------------------------------------------
    @property
    def aux_size(self) -> int:
        return 7

    @property
    def aux_names(self) -> tuple[str, ...]:
        """Names of the entries of `aux`."""
        return ("theta_motor", "omega_motor", "i_d", "i_q", "x_speed", "x_d", "x_q")

    @property
    def torque_constant(self) -> Float[Array, ""]:
        """`K_t = 1.5 p psi_f` (N·m/A): torque per ampere of `i_q` at `i_d = 0`."""
        return 1.5 * self.pole_pairs * self.psi_f

    @property
    def voltage_limit(self) -> Float[Array, ""]:
        """Largest dq voltage magnitude of the averaged inverter, `V_dc / sqrt 3` (V, peak phase)."""
        return self.V_dc / _SQRT3

    def current_gains(self) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
        """`(K_pd, K_pq, K_i)`: proportional gains `L omega_cc` (V/A) and integral gain
        `R_s omega_cc` (V/(A·s)) of the current loops, `omega_cc = 2 pi current_bandwidth`."""
        w = 2.0 * math.pi * self.current_bandwidth
        return self.L_d * w, self.L_q * w, self.R_s * w

    def speed_gains(self) -> tuple[Float[Array, ""], Float[Array, ""]]:
        """`(K_pw, K_iw)` of the speed loop: `J_t omega_sc / K_t` (A·s/rad) and `K_pw omega_sc / 4`
        (A/rad), `J_t = J_m (1 + load_inertia_ratio)`, `omega_sc = 2 pi speed_bandwidth`."""
        w = 2.0 * math.pi * self.speed_bandwidth
        kp = self.J_m * (1.0 + self.load_inertia_ratio) * w / self.torque_constant
        return kp, kp * w / 4.0

    def torque_em(self, i_d: Float[Array, ""], i_q: Float[Array, ""]) -> Float[Array, ""]:
        """Electromagnetic torque `1.5 p (psi_f i_q + (L_d - L_q) i_d i_q)` (N·m) from dq currents (A)."""
        return 1.5 * self.pole_pairs * (self.psi_f * i_q + (self.L_d - self.L_q) * i_d * i_q)

    # --- control and dynamics -----------------------------------------------------------------
    def _control(self, t, aux):
        """Controller and inverter: references, applied voltages and integrator derivatives."""
        _, omega_m, i_d, i_q, x_w, x_d, x_q = (aux[k] for k in range(7))
        omega_ref = self.speed(t)
        kpw, kiw = self.speed_gains()
        e_w = omega_ref - omega_m
        u_w = kpw * e_w + x_w
        i_q_ref = soft_clip(u_w, self.current_limit)
        dx_w = kiw * e_w * soft_clip_slope(u_w, self.current_limit)
        kpd, kpq, ki = self.current_gains()
        omega_e = self.pole_pairs * omega_m
        e_d = -i_d  # i_d* = 0
        e_q = i_q_ref - i_q
        vd_star = kpd * e_d + x_d - omega_e * self.L_q * i_q
        vq_star = kpq * e_q + x_q + omega_e * (self.L_d * i_d + self.psi_f)
        r = ((vd_star**2 + vq_star**2) / self.voltage_limit**2) ** (CLIP_ORDER // 2)
        scale = (1.0 + r) ** (-1.0 / CLIP_ORDER)
        slope = (1.0 + r) ** (-1.0 / CLIP_ORDER - 1.0)
        return {
            "omega_ref": omega_ref,
            "i_q_ref": i_q_ref,
            "v_d": scale * vd_star,
            "v_q": scale * vq_star,
            "dx_w": dx_w,
            "dx_d": ki * e_d * slope,
            "dx_q": ki * e_q * slope,
        }

    def shaft_torque(self, t, aux, theta_sun, omega_sun):
        """Torque on the sun (N·m) and `d aux / dt` (see the module docstring for the equations)."""
        theta_m, omega_m, i_d, i_q = aux[0], aux[1], aux[2], aux[3]
        c = self._control(t, aux)
        omega_e = self.pole_pairs * omega_m
        di_d = (c["v_d"] - self.R_s * i_d + omega_e * self.L_q * i_q) / self.L_d
        di_q = (c["v_q"] - self.R_s * i_q - omega_e * (self.L_d * i_d + self.psi_f)) / self.L_q
        t_shaft = self.shaft.torque(theta_m, omega_m, theta_sun, omega_sun)
        domega = (self.torque_em(i_d, i_q) - self.friction * omega_m - t_shaft) / self.J_m
        daux = jnp.stack([omega_m, domega, di_d, di_q, c["dx_w"], c["dx_d"], c["dx_q"]])
        return t_shaft, daux

    def steady_speed(self, torque_sun: ArrayLike = 0.0) -> Float[Array, ""]:
        """Steady sun speed (rad/s) under a steady shaft torque: the speed set point at t = 0
        (the PI speed loop has no steady error)."""
        return self.speed(_f(0.0)) + 0.0 * _f(torque_sun)

    def aux_init(self, omega_sun: Float[Array, ""], torque_sun: ArrayLike = 0.0) -> Float[Array, " 7"]:
        """Exact steady state at t = 0 for the sun at angle 0 turning at `omega_sun` (rad/s) while
        the shaft carries `torque_sun` (N·m); zeros for a start from standstill.

        `i_d = 0`, `i_q = (torque_sun + b omega) / K_t`, shaft twist `torque_sun / k_shaft`, speed
        integrator `x_w = sat^-1(i_q)`, current integrators preloaded with the voltages that hold
        the currents (through the inverse of the voltage limit). Consistent (all derivatives 0)
        when `omega_sun` is the set point at t = 0; at standstill with no torque every state and
        integrator is 0 (controller reset), whatever the set point. Fails (`eqx.error_if`)
        if the steady voltage or current exceeds the inverter's limits.
        """
        omega = _f(omega_sun)
        torque = _f(torque_sun)
        i_q = (torque + self.friction * omega) / self.torque_constant
        i_d = 0.0 * i_q
        i_q = eqx.error_if(
            i_q, jnp.abs(i_q) >= self.current_limit,
            "aux_init: the steady current exceeds motor.pmsm.current_limit; lower the load or "
            "raise the current limit",
            on_error="raise",  # the user needs the message, not a NaN (dtwin._config)
        )
        x_w = soft_clip_inverse(i_q, self.current_limit)
        omega_e = self.pole_pairs * omega
        v_d = self.R_s * i_d - omega_e * self.L_q * i_q
        v_q = self.R_s * i_q + omega_e * (self.L_d * i_d + self.psi_f)
        v_mag2 = v_d**2 + v_q**2
        v_mag2 = eqx.error_if(
            v_mag2, v_mag2 >= self.voltage_limit**2,
            "aux_init: the steady voltage exceeds V_dc/sqrt(3); raise motor.pmsm.V_dc or lower the "
            "speed (no field weakening is modelled)",
            on_error="raise",  # the user needs the message, not a NaN (dtwin._config)
        )
        r = (v_mag2 / self.voltage_limit**2) ** (CLIP_ORDER // 2)
        inv = (1.0 - r) ** (-1.0 / CLIP_ORDER)  # |v*| / |v| for the inverse radial clip
        x_d = inv * v_d + omega_e * self.L_q * i_q
        x_q = inv * v_q - omega_e * (self.L_d * i_d + self.psi_f)
        theta_m = self.shaft.twist_for(torque)
        return jnp.stack([theta_m, omega, i_d, i_q, x_w, x_d, x_q])

    def outputs(self, t, aux, theta_sun, omega_sun) -> dict[str, Float[Array, ""]]:
        """Observables: `omega_motor`, `omega_ref`, `theta_motor` (rad/s, rad), `torque_em`,
        `torque_shaft` (N·m), `i_d`, `i_q`, `i_q_ref`, `i_a`, `i_b`, `i_c` (A), `v_d`, `v_q` (V),
        `f_electrical` (Hz, `p omega_m / 2 pi`), `power_in` (`1.5 (v_d i_d + v_q i_q)`, W),
        `power_shaft` (to the sun, W), `power_copper` (`1.5 R_s (i_d² + i_q²)`), `power_friction`
        (`b omega_m²`), `power_shaft_damping`, `power_loss` (their sum, W) and `energy_stored`
        (J: magnetic `0.75 (L_d i_d² + L_q i_q²)` + rotor kinetic + shaft strain), so that
        `power_in = power_loss + power_shaft + d energy_stored / dt`."""
        theta_m, omega_m, i_d, i_q = aux[0], aux[1], aux[2], aux[3]
        c = self._control(t, aux)
        theta_e = self.pole_pairs * theta_m
        i_a, i_b, i_c = inverse_park(i_d, i_q, theta_e)
        t_shaft = self.shaft.torque(theta_m, omega_m, theta_sun, omega_sun)
        p_cu = 1.5 * self.R_s * (i_d**2 + i_q**2)
        p_fr = self.friction * omega_m**2
        p_damp = self.shaft.damping_power(omega_m - omega_sun)
        energy = (
            0.75 * (self.L_d * i_d**2 + self.L_q * i_q**2)
            + 0.5 * self.J_m * omega_m**2
            + self.shaft.strain_energy(theta_m - theta_sun)
        )
        return {
            "omega_motor": omega_m,
            "omega_ref": c["omega_ref"],
            "theta_motor": theta_m,
            "torque_em": self.torque_em(i_d, i_q),
            "torque_shaft": t_shaft,
            "i_d": i_d,
            "i_q": i_q,
            "i_q_ref": c["i_q_ref"],
            "v_d": c["v_d"],
            "v_q": c["v_q"],
            "i_a": i_a,
            "i_b": i_b,
            "i_c": i_c,
            "f_electrical": self.pole_pairs * omega_m / (2.0 * math.pi),
            "power_in": 1.5 * (c["v_d"] * i_d + c["v_q"] * i_q),
            "power_shaft": t_shaft * omega_sun,
            "power_copper": p_cu,
            "power_friction": p_fr,
            "power_shaft_damping": p_damp,
            "power_loss": p_cu + p_fr + p_damp,
            "energy_stored": energy,
        }
