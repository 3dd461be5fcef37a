"""Mesh excitation as calibrated transmission-error harmonics, one set per mesh type.

A real gear pair's excitation at the mesh harmonics comes from its tooth-profile deviations,
micro-geometry (tip and root relief, lead crowning) and the exact shape of its stiffness
waveform under load, none of which a gearbox's data sheet publishes. `MeshExcitation` adds a
static transmission error per mesh type as a Fourier series of the mesh phase ``phi`` (mesh
cycles),

.. math:: e(\\phi) = \\sum_{h=1}^{H} a_h \\cos(2\\pi h\\phi) + b_h \\sin(2\\pi h\\phi)   \\quad (m)

subtracted from every mesh deflection of that type (as :class:`TransmissionError`). Each
planet's mesh uses its own phase, so the planets' contributions keep the phasing of the tooth
geometry. The excitation is linear in ``(a_h, b_h)``: with the twin's other parameters fixed,
the dynamic mesh forces (hence the sensor signal) respond to it to first order exactly, which
is what `dtwin.identify.calibrate` uses to fit it from a healthy record. The cosine/sine form
(instead of amplitude/phase) keeps it linear and free of a phase wrap.

Reference: Welbourn (1979), "Fundamental knowledge of gear noise — a survey" (transmission
error as the main excitation of gear vibration); Smith (2003), *Gear Noise and Vibration*,
ch. 2–3.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..faults import mesh_phases
from .base import AbstractPart, Modulation


def _series(phase, cos_coef, sin_coef):
    h = jnp.arange(1, cos_coef.shape[0] + 1, dtype=jnp.float64)
    arg = 2.0 * jnp.pi * h * phase[..., None]
    return jnp.sum(cos_coef * jnp.cos(arg) + sin_coef * jnp.sin(arg), axis=-1)


class MeshExcitation(AbstractPart):
    """Transmission-error harmonics (m) of the sun-planet and ring-planet meshes (module docs).

    - `sun_cos`, `sun_sin`: ``a_h``, ``b_h`` of the sun-planet meshes, h = 1 … H (m).
    - `ring_cos`, `ring_sin`: the same for the ring-planet meshes (m).

    All zero leaves the dynamics unchanged.
    """

    sun_cos: Float[Array, " H"]
    sun_sin: Float[Array, " H"]
    ring_cos: Float[Array, " H"]
    ring_sin: Float[Array, " H"]

    def __check_init__(self):
        shapes = {jnp.shape(x) for x in (self.sun_cos, self.sun_sin, self.ring_cos,
                                          self.ring_sin)}
        if len(shapes) != 1 or len(next(iter(shapes))) != 1:
            raise ValueError("MeshExcitation: the four coefficient arrays need one shape (H,), "
                             f"got {sorted(shapes)}")

    @classmethod
    def zeros(cls, n_harmonics: int) -> MeshExcitation:
        """No excitation, with room for `n_harmonics` harmonics per mesh type."""
        z = jnp.zeros(n_harmonics)
        return cls(z, z, z, z)

    @property
    def n_harmonics(self) -> int:
        return int(jnp.shape(self.ring_cos)[0])

    def modulation(self, twin, t, q, qdot):
        ph_sp, ph_rp = mesh_phases(twin.lp, q.theta_s, q.theta_c, q.theta_r)
        z = jnp.zeros(twin.n_planets)
        e_sp = _series(ph_sp, self.sun_cos, self.sun_sin)
        e_rp = _series(ph_rp, self.ring_cos, self.ring_sin)
        return Modulation(z, z, z, z, e_sp, e_rp)


def excitation_from_table(table) -> MeshExcitation | None:
    """The part a spec's ``[mesh]`` excitation fields describe (None when absent or all zero)."""
    keys = ("excitation_sun_cos", "excitation_sun_sin", "excitation_ring_cos",
            "excitation_ring_sin")
    vals = [table.get(k) for k in keys]
    if all(v is None for v in vals):
        return None
    n = max(len(v) for v in vals if v is not None)
    arrs = []
    for v in vals:
        a = jnp.zeros(n) if v is None else jnp.asarray(list(v) + [0.0] * (n - len(v)),
                                                       dtype=jnp.float64)
        arrs.append(a)
    if not any(bool(jnp.any(a != 0)) for a in arrs):
        return None
    return MeshExcitation(*arrs)


