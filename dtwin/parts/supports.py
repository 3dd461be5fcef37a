"""Bearings and torsional supports: springs and dampers from the bodies to the housing.

Translational bearings are isotropic, so their forces are the same in the carrier frame as in
the fixed frame. Planet bearings connect each planet to its pin (`zeta`, `eta` are the bearing
deflections). Torsional supports connect the sun, ring and carrier rotations to ground
(a torsional spring on the planets is deliberately not offered: it would remove the gear
set's rigid-body rotation, reference.md §3). In the dynamics only the ring's torsional support
acts — the sun and carrier turn without bound and are held by the drive shaft and the load
(parts of their own); `k_torsion_sun` and `k_torsion_carrier` enter the twin's linear stiffness
matrix (modal analysis, where they stand for shafts to ground) but not the time simulation.

Damping: ``c = 2 zeta_support sqrt(k m)`` with the supported body's mass (or inertia for the
torsional supports).
"""

from __future__ import annotations

import jax.numpy as jnp

from .base import AbstractPart


class Supports(AbstractPart):
    """All bearings and torsional supports, with the stiffness and damping of `twin.lp`."""

    def spring_forces(self, twin, q):
        """Linear spring forces only (used for the twin's stiffness matrix)."""
        return self._forces(twin, q, None, modal=True)

    def _forces(self, twin, q, qdot, modal=False):
        from ..twin import Coords

        lp = twin.lp

        def c(k, m):
            return 2.0 * lp.zeta_support * jnp.sqrt(k * m)

        def f(k, m, x, v):
            out = -k * x
            if qdot is not None:
                out = out - c(k, m) * v
            return out

        v = qdot if qdot is not None else q  # unused when qdot is None
        mc_eff = lp.m_carrier + twin.n_planets * lp.m_planet
        return Coords(
            f(lp.k_bearing_sun, lp.m_sun, q.sun_xy, v.sun_xy),
            -lp.k_torsion_sun * q.theta_s if modal else jnp.zeros(()),
            f(lp.k_bearing_ring, lp.m_ring, q.ring_xy, v.ring_xy),
            f(lp.k_torsion_ring, lp.J_ring, q.theta_r, v.theta_r),
            f(lp.k_bearing_carrier, mc_eff, q.carrier_xy, v.carrier_xy),
            -lp.k_torsion_carrier * q.theta_c if modal else jnp.zeros(()),
            f(lp.k_bearing_planet, lp.m_planet, q.zeta, v.zeta),
            f(lp.k_bearing_planet, lp.m_planet, q.eta, v.eta),
            jnp.zeros_like(q.theta_p),
        )

    def forces(self, twin, t, q, qdot, aux, mesh):
        return self._forces(twin, q, qdot), jnp.zeros(0), {}
