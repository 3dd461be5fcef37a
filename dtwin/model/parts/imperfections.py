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
  with larger offsets carry less load (unequal load sharing). :func:`load_share_offsets` gives
  the clearances of stated load shares (a spec's ``imperfections.load_sharing``).
- `TransmissionError`: static transmission error of every mesh as a function of its phase.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..coords import unit_radial, unit_tangential
from ..faults import mesh_phases
from ..statics import static_balance
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
    """Static clearances (m) of each planet's sun and ring mesh: unequal load sharing.

    :func:`load_share_offsets` gives the clearances that produce stated load shares."""

    e_sp: Float[Array, " N"]
    e_rp: Float[Array, " N"]

    def modulation(self, twin, t, q, qdot):
        z = jnp.zeros(twin.n_planets)
        return Modulation(z, z, z, z, self.e_sp, self.e_rp)


def load_share_offsets(twin, shares, f_sun) -> Float[Array, " N"]:
    r"""Clearances ``e_i`` (m), the same on both meshes of planet ``i``, that give the planets
    the relative load shares `shares` (N values, read relative to their mean) in `twin`.

    Static model of `dtwin.simulation.simulate.initial_state` (the same balance): mean mesh stiffness,
    linear contact, the parts' linear springs, the carrier angle held and the twin's load
    torque on it. The mesh forces are ``f = K_m (L A z - C e)`` (``C`` puts ``e_i`` on both
    meshes of planet ``i``), so equilibrium ``K_z z = F + A^T L^T K_m C e`` makes the
    sun-mesh forces affine in ``e``: ``f_sp = f_0 + G e``. The clearances are the least-norm solution of
    ``G e = s_i mean(f_0) - f_0``; a common clearance of every planet moves the central members
    and changes no share, so the result has zero mean where the twin allows that freedom. The
    torsional twin with a sun held on its centre gives the closed form
    ``e_i = (1 - s_i) mean(f_0) / (2 k)``, ``1/k = 1/k_sp + 1/k_rp``; a floating sun takes up part
    of each clearance, and the solve accounts for it. The time-varying stiffness and one-sided
    contact move the shares of a running twin from the stated ones, by under 1 % on the paper's
    gearboxes.

    **Arguments:** `twin` (without the offsets); `shares` (N positive values); `f_sun`: input
    speed (Hz) at which the load torque (and the planets' centripetal pre-load) is taken.

    **Returns:** `e` (m), shape (N,); positive relieves a planet.
    """
    return _load_share_offsets(twin, jnp.asarray(shares, dtype=jnp.float64),
                               jnp.asarray(f_sun, dtype=jnp.float64))


@eqx.filter_jit
def _load_share_offsets(twin, shares, f_sun):
    """:func:`load_share_offsets` as one compiled program (a twin is built outside any `jit`;
    run operation by operation, its Jacobians cost seconds of compilation in every new
    process)."""
    lp, n = twin.lp, twin.n_planets
    s = shares / jnp.mean(shares)
    rs, _ = twin.kinematic_ratios
    A, keep, K, F, _ = static_balance(
        twin, 2.0 * jnp.pi * jnp.asarray(f_sun, dtype=jnp.float64) / rs)
    L = twin.deflection_matrix() @ A[:, keep]  # 2N x reduced coordinates
    km = jnp.concatenate([jnp.full((n,), lp.k_sun_planet), jnp.full((n,), lp.k_ring_planet)])
    C = jnp.concatenate([jnp.eye(n), jnp.eye(n)])
    z0 = jnp.linalg.solve(K, F)
    Z = jnp.linalg.solve(K, L.T @ (km[:, None] * C))  # dz/de
    f0 = lp.k_sun_planet * (L @ z0)[:n]
    G = lp.k_sun_planet * ((L @ Z)[:n] - jnp.eye(n))
    e, *_ = jnp.linalg.lstsq(G, s * jnp.mean(f0) - f0, rcond=1e-10)
    return e


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
