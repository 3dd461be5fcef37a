"""Bearings and torsional supports: springs and dampers from the bodies to the housing.

Translational bearings are isotropic, so their forces are the same in the carrier frame as in
the fixed frame. Planet bearings connect each planet to its pin (`zeta`, `eta` are the bearing
deflections). Torsional supports connect the sun, ring and carrier rotations to ground
(a torsional spring on the planets is deliberately not offered: it would remove the gear
set's rigid-body rotation, docs/references.md §3). In the dynamics only the ring's torsional support
acts — the sun and carrier turn without bound and are held by the drive shaft and the load
(parts of their own); `k_torsion_sun` and `k_torsion_carrier` enter the twin's linear stiffness
matrix (modal analysis, where they stand for shafts to ground) but not the time simulation.

Damping: ``c = 2 zeta_support sqrt(k m)`` with the supported body's mass (or inertia for the
torsional supports).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..coords import Coords
from .base import AbstractPart


class Supports(AbstractPart):
    """All bearings and torsional supports, with the stiffness and damping of `twin.lp`.

    Linear: contributes constant stiffness and damping matrices (`linear_springs`) that the
    twin adds once per solve, rather than forces evaluated at every step.
    """

    def _forces(self, twin, q, qdot, modal=False):
        lp = twin.lp

        def c(k, m):
            return 2.0 * lp.zeta_support * jnp.sqrt(k * m)

        def f(k, m, x, v):
            return -k * x - c(k, m) * v

        mc_eff = lp.m_carrier + twin.n_planets * lp.m_planet
        z0 = jnp.zeros(())
        return Coords(
            f(lp.k_bearing_sun, lp.m_sun, q.sun_xy, qdot.sun_xy),
            -lp.k_torsion_sun * q.theta_s if modal else z0,
            f(lp.k_bearing_ring, lp.m_ring, q.ring_xy, qdot.ring_xy),
            f(lp.k_torsion_ring, lp.J_ring, q.theta_r, qdot.theta_r),
            f(lp.k_bearing_carrier, mc_eff, q.carrier_xy, qdot.carrier_xy),
            -lp.k_torsion_carrier * q.theta_c if modal else z0,
            f(lp.k_bearing_planet, lp.m_planet, q.zeta, qdot.zeta),
            f(lp.k_bearing_planet, lp.m_planet, q.eta, qdot.eta),
            jnp.zeros_like(q.theta_p),
        )

    def _matrices(self, twin, modal):
        n = twin.n_dof
        zero = jnp.zeros(n)

        def fq(v):
            return twin.pack(self._forces(twin, twin.unpack(v), twin.unpack(zero), modal))

        def fv(v):
            return twin.pack(self._forces(twin, twin.unpack(zero), twin.unpack(v), modal))

        return -jax.jacfwd(fq)(zero), -jax.jacfwd(fv)(zero)

    def linear_springs(self, twin):
        """`(K, C)`: stiffness and damping matrices in the twin's coordinates `q`."""
        return self._matrices(twin, modal=False)

    def modal_springs(self, twin):
        """As `linear_springs`, with the sun and carrier torsional supports (shafts to ground)."""
        return self._matrices(twin, modal=True)
