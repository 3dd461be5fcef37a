"""The seam between the gearbox and what turns it: abstract drives and loads.

A *drive* produces the torque on the sun shaft (N·m) from its own states (`aux`: motor rotor
angle and speed, currents, controller integrators, …) and the sun's angle and speed. Every drive
includes the torsionally flexible shaft/coupling between its rotor and the sun, so the ideal
speed source (the paper's "traditional" model) and the motors differ only in what turns the
rotor end of that shaft. A *load* is the torque on the carrier (output), positive values
opposing the carrier's (CCW) rotation.

The twin (`dtwin/model/twin.py`) wraps a drive and a load into parts of the one ODE; they can also be
integrated against a rigid equivalent inertia for tests of the drive alone.
"""

from __future__ import annotations

import abc

import equinox as eqx
from jaxtyping import Array, Float


class AbstractDrive(eqx.Module):
    """Drive + shaft acting on the sun.

    Subclasses implement:

    - `aux_size` (property): number of own states.
    - `aux_init(omega_sun)`: states at `t = 0` for a sun turning at `omega_sun` (rad/s)
      (0 for a start from standstill).
    - `shaft_torque(t, aux, theta_sun, omega_sun) -> (torque, aux_dot)`: torque applied to the
      sun (N·m, positive = CCW, driving) and the time derivative of `aux`.
    - `outputs(t, aux, theta_sun, omega_sun) -> dict[str, scalar]`: observables (motor speed
      `omega_motor` rad/s, electromagnetic torque `torque_em` N·m, phase currents `i_a, i_b,
      i_c` A, input electrical power `power_in` W, …; what applies to the drive).
    """

    @property
    @abc.abstractmethod
    def aux_size(self) -> int: ...

    @abc.abstractmethod
    def aux_init(self, omega_sun: Float[Array, ""]) -> Float[Array, " n_aux"]: ...

    @abc.abstractmethod
    def shaft_torque(
        self,
        t: Float[Array, ""],
        aux: Float[Array, " n_aux"],
        theta_sun: Float[Array, ""],
        omega_sun: Float[Array, ""],
    ) -> tuple[Float[Array, ""], Float[Array, " n_aux"]]: ...

    def aux_steady(
        self, omega_sun: Float[Array, ""], torque_sun: Float[Array, ""]
    ) -> Float[Array, " n_aux"]:
        """States of a steady run at `omega_sun` (rad/s) delivering `torque_sun` (N·m) to the sun
        (shaft pre-twisted, controller integrators preloaded). Drives that can should override
        this; the default is `aux_init(omega_sun)` (the run then starts with a small transient).
        """
        import inspect

        if "torque_sun" in inspect.signature(self.aux_init).parameters:
            return self.aux_init(omega_sun, torque_sun=torque_sun)  # type: ignore[call-arg]
        return self.aux_init(omega_sun)

    @abc.abstractmethod
    def outputs(
        self,
        t: Float[Array, ""],
        aux: Float[Array, " n_aux"],
        theta_sun: Float[Array, ""],
        omega_sun: Float[Array, ""],
    ) -> dict[str, Float[Array, ""]]: ...


class AbstractLoad(eqx.Module):
    """Load torque on the carrier (N·m), opposing its rotation when positive."""

    @abc.abstractmethod
    def torque(
        self, t: Float[Array, ""], theta_carrier: Float[Array, ""], omega_carrier: Float[Array, ""]
    ) -> Float[Array, ""]: ...
