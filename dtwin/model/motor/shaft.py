"""The torsionally flexible shaft and coupling between a drive's rotor and the sun.

Every drive (:mod:`dtwin.model.motor.pmsm`, :mod:`dtwin.model.motor.induction_motor`,
:mod:`dtwin.model.motor.speed_source`) carries one `Shaft`, so that the "traditional" model (ideal
speed source) and the motor-coupled twin differ only in what turns the rotor end of the shaft.

The shaft is a massless torsional spring-damper (its inertia is lumped into the rotor and the sun):

    T_shaft = k_shaft (theta_m - theta_s) + c_shaft (omega_m - omega_s)

with `theta_m`, `omega_m` the rotor's and `theta_s`, `omega_s` the sun's absolute angle (rad) and
speed (rad/s), CCW positive (docs/conventions.md). `T_shaft` (N·m) drives the sun and brakes the
rotor.

Default values (docs/motor.md): a flexible jaw coupling sized for ~20 N·m in series with short
steel shafts, k_shaft = 2000 N·m/rad, c_shaft = 0.2 N·m·s/rad (torsional damping ratio ≈ 7 %, mode at ~225 Hz, for
a 3e-3 kg·m² rotor against a 1.5e-3 kg·m² load).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ...errors import SpecError

#: Default torsional stiffness of shaft + coupling (N·m/rad).
K_SHAFT_DEFAULT = 2000.0
#: Default torsional damping of shaft + coupling (N·m·s/rad).
C_SHAFT_DEFAULT = 0.2


def concrete_float(x: ArrayLike) -> float | None:
    """`float(x)` for a concrete scalar, `None` for a tracer (inside `jit`, `grad`, `vmap`)."""
    try:
        return float(x)
    except TypeError:  # jax.errors.ConcretizationTypeError / TracerArrayConversionError
        return None


class Shaft(eqx.Module):
    """Massless torsional spring-damper between a rotor and the sun.

    **Fields:**

    - `k_shaft`: torsional stiffness (N·m/rad), > 0.
    - `c_shaft`: torsional viscous damping (N·m·s/rad), >= 0.
    """

    k_shaft: Float[Array, ""]
    c_shaft: Float[Array, ""]

    def __init__(self, k_shaft: ArrayLike = K_SHAFT_DEFAULT, c_shaft: ArrayLike = C_SHAFT_DEFAULT):
        self.k_shaft = jnp.asarray(k_shaft, dtype=jnp.float64)
        self.c_shaft = jnp.asarray(c_shaft, dtype=jnp.float64)

    def __check_init__(self):
        k = concrete_float(self.k_shaft)
        c = concrete_float(self.c_shaft)
        if k is None or c is None:  # traced (inside jit/vmap/grad): checked at the boundary
            return
        problems = []
        if not k > 0.0:
            problems.append(("motor.k_shaft", f"shaft stiffness must be > 0 N·m/rad, got {k}"))
        if not c >= 0.0:
            problems.append(("motor.c_shaft", f"shaft damping must be >= 0 N·m·s/rad, got {c}"))
        if problems:
            raise SpecError(problems)

    def torque(
        self,
        theta_rotor: Float[Array, ""],
        omega_rotor: Float[Array, ""],
        theta_sun: Float[Array, ""],
        omega_sun: Float[Array, ""],
    ) -> Float[Array, ""]:
        """Torque transmitted to the sun, `k (theta_m - theta_s) + c (omega_m - omega_s)`.

        **Arguments:** rotor and sun angles (rad) and speeds (rad/s).

        **Returns:** torque on the sun (N·m, positive = CCW, driving); the rotor gets its negative.
        """
        return self.k_shaft * (theta_rotor - theta_sun) + self.c_shaft * (omega_rotor - omega_sun)

    def strain_energy(self, twist: Float[Array, ""]) -> Float[Array, ""]:
        """Elastic energy `0.5 k twist²` (J) of a twist `theta_m - theta_s` (rad)."""
        return 0.5 * self.k_shaft * twist**2

    def damping_power(self, twist_rate: Float[Array, ""]) -> Float[Array, ""]:
        """Power dissipated in the damper `c (omega_m - omega_s)²` (W)."""
        return self.c_shaft * twist_rate**2

    def twist_for(self, torque: ArrayLike) -> Float[Array, ""]:
        """Static twist `T / k` (rad) that transmits a steady torque `T` (N·m)."""
        return jnp.asarray(torque, dtype=jnp.float64) / self.k_shaft
