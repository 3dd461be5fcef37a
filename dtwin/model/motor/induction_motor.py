"""Induction (asynchronous) motor fed by a V/f drive, driving the sun through the flexible shaft.

Dynamic equivalent-circuit model (Krause) in the synchronous frame, which rotates with the supply
voltage vector at `omega_e(t) = p omega_ref(t)` (the V/f drive's frequency command; `omega_ref`
is the synchronous speed set point, a `SpeedProfile`). States are the stator and rotor flux
linkages (V·s, amplitude-invariant dq, rotor quantities referred to the stator):

    dpsi_ds/dt = v_ds - R_s i_ds + omega_e psi_qs       dpsi_dr/dt = -R_r i_dr + (omega_e - omega_r) psi_qr
    dpsi_qs/dt = v_qs - R_s i_qs - omega_e psi_ds       dpsi_qr/dt = -R_r i_qr - (omega_e - omega_r) psi_dr
    i_s = (L_r psi_s - L_m psi_r) / D,  i_r = (L_s psi_r - L_m psi_s) / D,  D = L_s L_r - L_m²
    L_s = L_ls + L_m,  L_r = L_lr + L_m,  omega_r = p omega_m
    T_em = 1.5 p (psi_ds i_qs - psi_qs i_ds)
    J_m domega_m/dt = T_em - b omega_m - T_shaft

V/f drive (averaged, sinusoidal): `v_ds = V(f_e)`, `v_qs = 0` with the phase-voltage amplitude

    V(f) = V_n (b_0 + (1 - b_0) |f| / f_n),   V_n = sqrt(2/3) V_rated (line rms -> phase peak)

(`b_0` = `boost` for the resistive drop at low frequency). The supply angle is the closed-form
integral `theta_e(t) = p int omega_ref dt`, and the phase currents are `i_s` rotated by it
(inverse Park): their frequency is the supply frequency `f_e`, above `p f_mech` by the slip.
Under load the rotor turns below synchronous speed; with the defaults and 1800 rpm synchronous
(60 Hz, 2 pole pairs) a load of ~7 N·m gives 1782 rpm (slip 1 %, as on the paper's bench).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ...errors import SpecError
from .drive_base import AbstractDrive
from .pmsm import inverse_park
from .shaft import Shaft, concrete_float
from .speed_source import SpeedProfile, rpm_to_rad_s

#: Default parameters: a 4 kW, 4-pole (2 pole pairs) squirrel-cage machine with the equivalent
#: circuit of the 4 kW / 400 V / 50 Hz example machine widely used in Simulink studies, run from a
#: 460 V / 60 Hz V/f drive (≈ the same volts per hertz). See docs/motor.md.
INDUCTION_DEFAULTS: dict[str, float] = {
    "R_s": 1.405,  # ohm
    "R_r": 1.395,  # ohm (referred to the stator)
    "L_ls": 5.839e-3,  # H
    "L_lr": 5.839e-3,  # H
    "L_m": 0.1722,  # H
    "pole_pairs": 2,
    "J_m": 0.0131,  # kg·m²
    "friction": 2.985e-3,  # N·m·s/rad
    "rated_voltage": 460.0,  # V, line-to-line rms at rated_frequency
    "rated_frequency": 60.0,  # Hz
    "boost": 0.02,  # fraction of the rated voltage at 0 Hz
}


def _f(x: ArrayLike) -> Float[Array, ""]:
    return jnp.asarray(x, dtype=jnp.float64)


def _cmul(a, b):
    return (a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


def _cdiv(a, b):
    den = b[0] ** 2 + b[1] ** 2
    return ((a[0] * b[0] + a[1] * b[1]) / den, (a[1] * b[0] - a[0] * b[1]) / den)


class InductionMotor(AbstractDrive):
    """Induction motor + V/f drive + flexible shaft, driving the sun.

    State `aux = [theta_m, omega_m, psi_ds, psi_qs, psi_dr, psi_qr]`: rotor angle (rad) and speed
    (rad/s), stator and rotor flux linkages in the synchronous frame (V·s).

    **Fields** (SI): `speed` (`SpeedProfile`, the synchronous speed set point `2 pi f_e / p`,
    rad/s), `shaft` (`Shaft`), `R_s`, `R_r` (ohm), `L_ls`, `L_lr`, `L_m` (H), `pole_pairs`
    (static int), `J_m` (kg·m²), `friction` (N·m·s/rad), `rated_voltage` (V line rms),
    `rated_frequency` (Hz), `boost` (1). Defaults: `INDUCTION_DEFAULTS`.
    """

    speed: SpeedProfile
    shaft: Shaft
    R_s: Float[Array, ""]
    R_r: Float[Array, ""]
    L_ls: Float[Array, ""]
    L_lr: Float[Array, ""]
    L_m: Float[Array, ""]
    pole_pairs: int = eqx.field(static=True)
    J_m: Float[Array, ""]
    friction: Float[Array, ""]
    rated_voltage: Float[Array, ""]
    rated_frequency: Float[Array, ""]
    boost: Float[Array, ""]

    def __init__(
        self,
        speed: SpeedProfile | None = None,
        shaft: Shaft | None = None,
        *,
        R_s: ArrayLike = INDUCTION_DEFAULTS["R_s"],
        R_r: ArrayLike = INDUCTION_DEFAULTS["R_r"],
        L_ls: ArrayLike = INDUCTION_DEFAULTS["L_ls"],
        L_lr: ArrayLike = INDUCTION_DEFAULTS["L_lr"],
        L_m: ArrayLike = INDUCTION_DEFAULTS["L_m"],
        pole_pairs: int = int(INDUCTION_DEFAULTS["pole_pairs"]),
        J_m: ArrayLike = INDUCTION_DEFAULTS["J_m"],
        friction: ArrayLike = INDUCTION_DEFAULTS["friction"],
        rated_voltage: ArrayLike = INDUCTION_DEFAULTS["rated_voltage"],
        rated_frequency: ArrayLike = INDUCTION_DEFAULTS["rated_frequency"],
        boost: ArrayLike = INDUCTION_DEFAULTS["boost"],
    ):
        """Defaults: `INDUCTION_DEFAULTS`; `speed` defaults to a 0.5 s V/f ramp to 1800 rpm
        synchronous (60 Hz with 2 pole pairs), `shaft` to `Shaft()`."""
        self.speed = SpeedProfile.ramp(rpm_to_rad_s(1800.0), 0.5) if speed is None else speed
        self.shaft = Shaft() if shaft is None else shaft
        self.R_s = _f(R_s)
        self.R_r = _f(R_r)
        self.L_ls = _f(L_ls)
        self.L_lr = _f(L_lr)
        self.L_m = _f(L_m)
        self.pole_pairs = int(pole_pairs)
        self.J_m = _f(J_m)
        self.friction = _f(friction)
        self.rated_voltage = _f(rated_voltage)
        self.rated_frequency = _f(rated_frequency)
        self.boost = _f(boost)

    def __check_init__(self):
        problems = []
        if self.pole_pairs < 1:
            problems.append(("motor.induction.pole_pairs", f"must be an integer >= 1, got {self.pole_pairs}"))
        for name in ("R_s", "R_r", "L_ls", "L_lr", "L_m", "J_m", "rated_voltage", "rated_frequency"):
            v = concrete_float(getattr(self, name))
            if v is not None and not v > 0.0:
                problems.append((f"motor.induction.{name}", f"must be > 0 (SI units), got {v}"))
        fr = concrete_float(self.friction)
        if fr is not None and not fr >= 0.0:
            problems.append(("motor.induction.friction", f"must be >= 0 N·m·s/rad, got {fr}"))
        b = concrete_float(self.boost)
        if b is not None and not 0.0 <= b < 1.0:
            problems.append(("motor.induction.boost", f"must be in [0, 1) (fraction of rated voltage), got {b}"))
        if problems:
            raise SpecError(problems)

    # --- derived quantities -------------------------------------------------------------------
    @property
    def aux_size(self) -> int:
        return 6

    @property
    def aux_names(self) -> tuple[str, ...]:
        """Names of the entries of `aux`."""
        return ("theta_motor", "omega_motor", "psi_ds", "psi_qs", "psi_dr", "psi_qr")

    def supply_frequency(self, t: Float[Array, ""]) -> Float[Array, ""]:
        """V/f drive's output frequency `f_e = p omega_ref(t) / 2 pi` (Hz)."""
        return self.pole_pairs * self.speed(t) / (2.0 * math.pi)

    def supply_voltage(self, f_e: Float[Array, ""]) -> Float[Array, ""]:
        """V/f law: phase-voltage amplitude `V_n (b_0 + (1 - b_0) |f_e| / f_n)` (V peak) at `f_e` (Hz)."""
        v_n = math.sqrt(2.0 / 3.0) * self.rated_voltage
        return v_n * (self.boost + (1.0 - self.boost) * jnp.abs(f_e) / self.rated_frequency)

    def currents(self, psi: Float[Array, " 4"]):
        """Stator and rotor dq currents (A) from the flux linkages `[psi_ds, psi_qs, psi_dr, psi_qr]` (V·s)."""
        l_s = self.L_ls + self.L_m
        l_r = self.L_lr + self.L_m
        det = l_s * l_r - self.L_m**2
        i_ds = (l_r * psi[0] - self.L_m * psi[2]) / det
        i_qs = (l_r * psi[1] - self.L_m * psi[3]) / det
        i_dr = (l_s * psi[2] - self.L_m * psi[0]) / det
        i_qr = (l_s * psi[3] - self.L_m * psi[1]) / det
        return i_ds, i_qs, i_dr, i_qr

    def steady_fluxes(self, omega_m: ArrayLike, f_e: ArrayLike) -> Float[Array, " 4"]:
        """Sinusoidal steady state (phasors in the synchronous frame) at rotor speed `omega_m`
        (rad/s) and supply frequency `f_e` (Hz): `[psi_ds, psi_qs, psi_dr, psi_qr]` (V·s).

        Solves `V = R_s i_s + j omega_e psi_s`, `0 = R_r i_r + j (omega_e - omega_r) psi_r`.
        """
        omega_e = 2.0 * math.pi * _f(f_e)
        slip_w = omega_e - self.pole_pairs * _f(omega_m)
        l_s = self.L_ls + self.L_m
        l_r = self.L_lr + self.L_m
        v = (self.supply_voltage(_f(f_e)), 0.0 * omega_e)
        z_r = (self.R_r, slip_w * l_r)
        a = _cdiv((omega_e * slip_w * self.L_m**2, 0.0 * omega_e), z_r)
        z = (self.R_s + a[0], omega_e * l_s + a[1])
        i_s = _cdiv(v, z)
        i_r = _cdiv(_cmul((0.0 * slip_w, -slip_w * self.L_m), i_s), z_r)
        psi_s = (l_s * i_s[0] + self.L_m * i_r[0], l_s * i_s[1] + self.L_m * i_r[1])
        psi_r = (self.L_m * i_s[0] + l_r * i_r[0], self.L_m * i_s[1] + l_r * i_r[1])
        return jnp.stack([psi_s[0], psi_s[1], psi_r[0], psi_r[1]])

    def steady_torque(self, omega_m: ArrayLike, f_e: ArrayLike) -> Float[Array, ""]:
        """Steady electromagnetic torque (N·m) at rotor speed `omega_m` (rad/s), supply `f_e` (Hz)."""
        psi = self.steady_fluxes(omega_m, f_e)
        i_ds, i_qs, _, _ = self.currents(psi)
        return 1.5 * self.pole_pairs * (psi[0] * i_qs - psi[1] * i_ds)

    def steady_speed(self, torque_sun: ArrayLike = 0.0, f_e: ArrayLike | None = None) -> Float[Array, ""]:
        """Rotor (= sun) speed (rad/s) at which `T_em - b omega = torque_sun` (N·m) on the stable
        branch, at supply frequency `f_e` (Hz; default: the V/f command at t = 0).

        Newton's method in the speed from synchronous speed (30 iterations; monotone, since the
        torque is concave in the slip below the breakdown slip), differentiable by the implicit
        function theorem (derivatives w.r.t. the motor's parameters and the load). Fails (`eqx.error_if`) when the
        load exceeds the breakdown torque.
        """
        f = self.supply_frequency(_f(0.0)) if f_e is None else _f(f_e)
        load = _f(torque_sun)
        w_sync = 2.0 * math.pi * f / self.pole_pairs

        def residual(w):
            return self.steady_torque(w, f) - self.friction * w - load

        def newton(_, w):
            return w - residual(w) / jax.grad(residual)(w)

        # Iterate without differentiating the loop; one final Newton step carries the implicit
        # derivative dw/dtheta = -(dr/dtheta) / (dr/dw) (implicit function theorem).
        w_star = jax.lax.stop_gradient(jax.lax.fori_loop(0, 30, newton, jax.lax.stop_gradient(w_sync)))
        w = w_star - residual(w_star) / jax.lax.stop_gradient(jax.grad(residual)(w_star))
        res = residual(w_star)
        return eqx.error_if(
            w, ~(jnp.abs(res) <= 1e-6 * (1.0 + jnp.abs(load))) | (w > w_sync),
            "InductionMotor.steady_speed: no stable operating point; the load torque exceeds the "
            "breakdown torque at this supply frequency (lower the load or raise rated_voltage)",
            on_error="raise",  # the user needs the message, not a NaN (dtwin._config)
        )

    def aux_init(self, omega_sun: Float[Array, ""], torque_sun: ArrayLike = 0.0) -> Float[Array, " 6"]:
        """State at t = 0 for the sun at angle 0 turning at `omega_sun` (rad/s) with shaft torque
        `torque_sun` (N·m): steady fluxes at that speed and the V/f command at t = 0, shaft twist
        `torque_sun / k_shaft`. Consistent (all derivatives 0) when
        `omega_sun = steady_speed(torque_sun)`; zeros-plus-fluxes for a start from standstill.
        """
        omega = _f(omega_sun)
        psi = self.steady_fluxes(omega, self.supply_frequency(_f(0.0)))
        return jnp.concatenate([jnp.stack([self.shaft.twist_for(torque_sun), omega]), psi])

    # --- dynamics -----------------------------------------------------------------------------
    def _electrical(self, t, aux):
        omega_m = aux[1]
        psi = aux[2:6]
        omega_e = self.pole_pairs * self.speed(t)
        v_d = self.supply_voltage(omega_e / (2.0 * math.pi))
        i_ds, i_qs, i_dr, i_qr = self.currents(psi)
        slip_w = omega_e - self.pole_pairs * omega_m
        dpsi = jnp.stack([
            v_d - self.R_s * i_ds + omega_e * psi[1],
            -self.R_s * i_qs - omega_e * psi[0],
            -self.R_r * i_dr + slip_w * psi[3],
            -self.R_r * i_qr - slip_w * psi[2],
        ])
        torque = 1.5 * self.pole_pairs * (psi[0] * i_qs - psi[1] * i_ds)
        return v_d, (i_ds, i_qs, i_dr, i_qr), dpsi, torque

    def shaft_torque(self, t, aux, theta_sun, omega_sun):
        """Torque on the sun (N·m) and `d aux / dt` (see the module docstring for the equations)."""
        theta_m, omega_m = aux[0], aux[1]
        _, _, dpsi, t_em = self._electrical(t, aux)
        t_shaft = self.shaft.torque(theta_m, omega_m, theta_sun, omega_sun)
        domega = (t_em - self.friction * omega_m - t_shaft) / self.J_m
        return t_shaft, jnp.concatenate([jnp.stack([omega_m, domega]), dpsi])

    def outputs(self, t, aux, theta_sun, omega_sun) -> dict[str, Float[Array, ""]]:
        """Observables: `omega_motor`, `omega_ref` (synchronous set point), `theta_motor`,
        `torque_em`, `torque_shaft`, `i_d`, `i_q` (stator, synchronous frame), `v_d`, `v_q`,
        `i_a`, `i_b`, `i_c` (A), `f_electrical` (supply frequency, Hz), `slip` (1),
        `power_in` (`1.5 v_d i_ds`, W), `power_shaft`, `power_copper` (`1.5 (R_s |i_s|² +
        R_r |i_r|²)`), `power_friction`, `power_shaft_damping`, `power_loss` (W) and
        `energy_stored` (J: magnetic `0.75 (psi_s . i_s + psi_r . i_r)` + rotor kinetic + shaft
        strain), so that `power_in = power_loss + power_shaft + d energy_stored / dt`."""
        theta_m, omega_m = aux[0], aux[1]
        psi = aux[2:6]
        v_d, (i_ds, i_qs, i_dr, i_qr), _, t_em = self._electrical(t, aux)
        omega_ref = self.speed(t)
        theta_e = self.pole_pairs * self.speed.angle(t)
        i_a, i_b, i_c = inverse_park(i_ds, i_qs, theta_e)
        t_shaft = self.shaft.torque(theta_m, omega_m, theta_sun, omega_sun)
        p_cu = 1.5 * (self.R_s * (i_ds**2 + i_qs**2) + self.R_r * (i_dr**2 + i_qr**2))
        p_fr = self.friction * omega_m**2
        p_damp = self.shaft.damping_power(omega_m - omega_sun)
        magnetic = 0.75 * (psi[0] * i_ds + psi[1] * i_qs + psi[2] * i_dr + psi[3] * i_qr)
        energy = magnetic + 0.5 * self.J_m * omega_m**2 + self.shaft.strain_energy(theta_m - theta_sun)
        safe = jnp.where(jnp.abs(omega_ref) > 1e-9, omega_ref, 1.0)
        slip = jnp.where(jnp.abs(omega_ref) > 1e-9, (omega_ref - omega_m) / safe, 0.0)
        return {
            "omega_motor": omega_m,
            "omega_ref": omega_ref,
            "theta_motor": theta_m,
            "torque_em": t_em,
            "torque_shaft": t_shaft,
            "i_d": i_ds,
            "i_q": i_qs,
            "v_d": v_d,
            "v_q": 0.0 * v_d,
            "i_a": i_a,
            "i_b": i_b,
            "i_c": i_c,
            "f_electrical": self.pole_pairs * omega_ref / (2.0 * math.pi),
            "slip": slip,
            "power_in": 1.5 * v_d * i_ds,
            "power_shaft": t_shaft * omega_sun,
            "power_copper": p_cu,
            "power_friction": p_fr,
            "power_shaft_damping": p_damp,
            "power_loss": p_cu + p_fr + p_damp,
            "energy_stored": energy,
        }
