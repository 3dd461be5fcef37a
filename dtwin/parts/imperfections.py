"""Manufacturing and assembly imperfections as parts (all zero = the ideal gearbox).

Each imperfection changes the meshes through the mesh phase and/or an excitation subtracted
from the mesh deflection (docs/conventions.md, "Mesh deflection"):

- `PlanetPositionErrors`: planet i sits at ``psi_i + dpsi_i`` on the carrier. Its mesh phases
  shift by ``-Zs dpsi_i / 2 pi`` (sun) and ``+Zr dpsi_i / 2 pi`` (ring). With
  ``pin_offset=True`` (default) its pin also moves by ``a dpsi_i`` along ``e_t`` against a sun
  and ring held on their centres, which changes both mesh deflections by
  ``-a dpsi cos(alpha)`` (a planet placed ahead relieves both its meshes: unequal load
  sharing, which the planet's rotation cannot absorb). With ``pin_offset=False`` only the
  phases shift: the gearbox whose floating central member takes up the offsets (a floating
  sun or ring moves by the offsets' ``1, cos psi, sin psi`` components, which for three
  planets are all of them: equal load sharing; Kahraman, "Load sharing characteristics of
  planetary transmissions", Mech. Mach. Theory 29 (1994) 1151–1165), and the same planets as
  ``imperfections.planet_position_errors`` of a spec (`dtwin.spec.lumped_from_spec`, which
  moves the planet angles and keeps the load shared equally). Breaks the sideband
  cancellation of equally spaced planets (docs/references.md §2): sidebands at every multiple
  of f_carrier.
- `SunEccentricity`: the sun's centre runs out by `e` (m), the offset turning with the sun:
  carrier-frame direction ``theta_s - theta_c + phase``.
- `CarrierEccentricity`: every pin is offset by the same vector `e` (m) at carrier-frame angle
  `phase` (turns with the carrier).
- `MeshOffsets`: a static extra clearance (m, positive = relieved) per planet and mesh; planets
  with larger offsets carry less load (unequal load sharing).
- `TransmissionError`: static transmission error of every mesh as a function of its phase.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..coords import unit_radial, unit_tangential
from ..faults import mesh_phases
from ..stiffness import transmission_error
from .base import AbstractPart, Modulation


def _lines_of_action(lp):
    psi = lp.planet_angles
    er, et = unit_radial(psi), unit_tangential(psi)
    n_sp = unit_tangential(psi - lp.alpha_sp)
    n_rp = jnp.sin(lp.alpha_rp) * er - jnp.cos(lp.alpha_rp) * et
    return n_sp, n_rp


class PlanetPositionErrors(AbstractPart):
    """Angular position errors of the planets on the carrier, `dpsi` (rad), shape (N,).

    `pin_offset`: whether the pins' offsets ``a dpsi`` load the meshes (sun and ring held on
    their centres: unequal load sharing) or a floating member takes them up (mesh phases only;
    module docs)."""

    dpsi: Float[Array, " N"]
    pin_offset: bool = eqx.field(static=True, default=True)

    def modulation(self, twin, t, q, qdot):
        lp = twin.lp
        two_pi = 2.0 * jnp.pi
        a = lp.centre_distance if self.pin_offset else 0.0
        return Modulation(
            jnp.zeros_like(self.dpsi),
            jnp.zeros_like(self.dpsi),
            -lp.z_sun * self.dpsi / two_pi,
            lp.z_ring * self.dpsi / two_pi,
            a * self.dpsi * jnp.cos(lp.alpha_sp),
            a * self.dpsi * jnp.cos(lp.alpha_rp),
        )


class SunEccentricity(AbstractPart):
    """Sun run-out: centre offset `e` (m) turning with the sun, at angle `phase` (rad)."""

    e: Float[Array, ""]
    phase: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.zeros(()))

    def modulation(self, twin, t, q, qdot):
        n_sp, _ = _lines_of_action(twin.lp)
        ang = q.theta_s - q.theta_c + self.phase
        ecc = self.e * jnp.stack([jnp.cos(ang), jnp.sin(ang)])
        z = jnp.zeros(twin.n_planets)
        return Modulation(z, z, z, z, -(n_sp @ ecc), z)


class CarrierEccentricity(AbstractPart):
    """Carrier eccentricity: all pins offset by `e` (m) at carrier-frame angle `phase` (rad)."""

    e: Float[Array, ""]
    phase: Float[Array, ""] = eqx.field(default_factory=lambda: jnp.zeros(()))

    def modulation(self, twin, t, q, qdot):
        n_sp, n_rp = _lines_of_action(twin.lp)
        ecc = self.e * jnp.stack([jnp.cos(self.phase), jnp.sin(self.phase)])
        z = jnp.zeros(twin.n_planets)
        # pins displaced by ecc: delta_sp changes by -n_sp.ecc, delta_rp by +n_rp.ecc
        return Modulation(z, z, z, z, n_sp @ ecc, -(n_rp @ ecc))


class MeshOffsets(AbstractPart):
    """Static clearances (m) of each planet's sun and ring mesh: unequal load sharing."""

    e_sp: Float[Array, " N"]
    e_rp: Float[Array, " N"]

    def modulation(self, twin, t, q, qdot):
        z = jnp.zeros(twin.n_planets)
        return Modulation(z, z, z, z, self.e_sp, self.e_rp)


class TransmissionError(AbstractPart):
    """Static transmission error ``A sum_h a_h sin(2 pi h phase + phi_h)`` (m) on both meshes.

    `amplitude` (m), `harmonics` relative amplitudes, `phases` (rad). The ring mesh uses the
    same profile; its phase is the ring mesh's own.
    """

    amplitude: Float[Array, ""]
    harmonics: Float[Array, " H"] = eqx.field(default_factory=lambda: jnp.ones(1))
    phases: Float[Array, " H"] = eqx.field(default_factory=lambda: jnp.zeros(1))

    def modulation(self, twin, t, q, qdot):
        ph_sp, ph_rp = mesh_phases(twin.lp, q.theta_s, q.theta_c, q.theta_r)
        z = jnp.zeros(twin.n_planets)
        e_sp = transmission_error(ph_sp, self.amplitude, self.harmonics, self.phases)
        e_rp = transmission_error(ph_rp, self.amplitude, self.harmonics, self.phases)
        return Modulation(z, z, z, z, e_sp, e_rp)
