"""Local tooth faults with continuous severity, as losses of mesh stiffness.

A fault *subtracts* stiffness from the mesh(es) its tooth is in while that tooth is in contact
(docs/conventions.md, "Mesh stiffness and faults"):

.. math:: k_{mesh,i}(t) = k_{healthy}(\\phi_i) - \\Delta k_i(t),\\qquad
          \\Delta k_i = c' \\; w(u_i) \\; f(\\text{severity}, u_i)

with ``c'`` the single-pair stiffness of that mesh (:func:`dtwin.model.stiffness.single_pair_from_mean`),
``u_i`` the time since the faulty tooth entered contact with planet ``i`` (mesh cycles),
``w`` a smooth box over the tooth's contact interval ``[0, eps)`` and ``f`` the fraction of a
tooth pair's stiffness the fault removes. Severity 0 gives ``Δk = 0`` exactly, so the faulty
stiffness is bit-identical to the healthy one.

**Severity → stiffness (the one place where this mapping lives; docs/references.md §7):**

- :class:`MissingTooth`: severity = fraction of the face width removed (1 = the whole tooth).
  Stiffness is proportional to the loaded face width, so ``f = severity`` for the whole contact
  interval: a fully missing tooth removes one pair, ``1.75 c' → 0.75 c'`` in double contact and
  ``c' → 0`` in single contact.
- :class:`Pitting`: severity = fraction of the flank area *inside the pitting band* that is lost
  (pits form around the pitch line, in the single-contact region: ISO 10825 / ASM Handbook
  vol. 19 on surface fatigue). The band is a smooth box of the contact path centred at
  ``band_centre·eps`` (default 0.5: pitch point near mid-path) of width ``band_width·eps``
  (default 0.4) mesh cycles; ``f = severity · band(u)``. The fraction of the whole active flank
  lost is ``severity · band_width``.
- :class:`RootCrack`: severity = crack depth ``q`` over tooth root thickness ``h``. In the
  potential-energy (beam) method of Yang & Lin (1987) and Tian (2004), the cracked tooth's
  section above the crack is thinned to ``h - q`` (the assumption of Wu, Zuo & Parey, J. Sound
  Vib. 317 (2008) 608–624, here on a uniform-section cantilever): its bending compliance grows by
  ``(h/(h-q))^3`` and its shear and axial compliances by ``h/(h-q)``. With ``w_b``, ``w_s`` the
  shares of the healthy pair's compliance due to the cracked tooth's bending and shear+axial
  deformation, the pair keeps the fraction ``1 / (1 + w_b((1-s)^{-3} - 1) + w_s((1-s)^{-1} - 1))``
  of its stiffness, so

  .. math:: g(s) = \\frac{w_b (1 - u^3) + w_s (u^2 - u^3)}{u^3 (1 - w_b - w_s) + w_b + w_s u^2},
            \\quad u = 1 - s

  (``g(0) = 0`` exactly, ``g(1) = 1``: a root crack through the whole tooth removes the pair like a
  missing tooth). Default shares ``w_b = 0.30``, ``w_s = 0.09`` are this project's estimate for
  a standard 20° steel pair from the potential-energy components (Hertzian ≈ 7 %, fillet
  foundation ≈ 15 % of the pair compliance, the rest shared by the two teeth); change them per
  fault if a detailed calculation is available. ``f = g(severity)``.

**The loss's shape.** Every fault's window ``w`` is a smooth box from ``-spread`` to
``eps + spread`` mesh cycles after the tooth enters contact, its edges sigmoids of width
``ramp`` (defaults :data:`WINDOW_EDGE` and 0: the loss follows the tooth's contact). A larger
``ramp`` makes the loss rise and fall gradually; a positive ``spread`` (up to
:data:`MAX_SPREAD`) lets it be felt beyond the tooth's own contact (load sharing with the
neighbouring pairs); a negative one (down to :data:`MIN_SPREAD`) confines it to the middle of
the contact, about the pitch point, where pits and spalls form. For a missing tooth of severity
``s`` the stiffness removed over a passage is ``s c' (eps + 2 spread)``: a record that sees
only that integral (the low-frequency comb of the tooth's passes) cannot tell a short deep loss
from a long shallow one, which is why :mod:`dtwin.identify.severity` profiles the shape.

**Contact windows** follow the mesh phase of docs/conventions.md (:func:`mesh_phases`): sun
tooth ``j`` is in contact with planet ``i`` while ``(phase_sp_i - j) mod Zs in [0, eps_sp)``,
ring tooth ``j`` while ``(phase_rp_i - j) mod Zr in [0, eps_rp)``. Planet teeth are counted with
the planet's spin relative to the carrier (:func:`planet_tooth_phases`): planet tooth ``k`` is in
the sun mesh while ``(q_sp_i - k) mod Zp in [0, eps_sp)`` and in the ring mesh while
``(q_rp_i - k) mod Zp in [0, eps_rp)``. The edges of every window are sigmoids of width
:data:`WINDOW_EDGE` mesh cycles, so the loss is smooth (gradients exist, an adaptive solver
resolves the pulses with ``dtmax`` below a pulse).
"""

from __future__ import annotations

import abc
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..errors import SpecError
from .lumped import LumpedParameters
from .stiffness import mesh_stiffness_waveform, single_pair_from_mean

__all__ = [
    "REFERENCES",
    "WINDOW_EDGE",
    "AbstractFault",
    "MissingTooth",
    "Pitting",
    "RootCrack",
    "crack_loss_fraction",
    "faults_from_table",
    "make_fault",
    "mesh_phases",
    "mesh_stiffnesses",
    "parse_fault",
    "peak_stiffness_loss",
    "planet_ring_delay",
    "planet_tooth_phases",
    "severity_for_peak_loss",
    "stiffness_loss_profile",
    "total_stiffness_loss",
    "tooth_window",
]

#: Edge width of the smooth contact windows (mesh cycles): each edge is ``sigmoid(x / WINDOW_EDGE)``,
#: rising from 10 % to 90 % over ``4.4 WINDOW_EDGE`` = 0.22 mesh cycles. A fault's own `ramp`
#: (default this value) sets the edges of its loss.
WINDOW_EDGE = 0.05
#: Largest `ramp` of a fault (mesh cycles): a loss rising over ``4.4 × 0.5 ≈ 2`` cycles.
MAX_RAMP = 0.5
#: Largest `spread` of a fault (mesh cycles): how far beyond its own contact interval, either
#: side, a tooth's loss may still be felt by the mesh.
MAX_SPREAD = 3.0
#: Smallest `spread` of a fault (mesh cycles): a negative spread confines the loss to the middle
#: of the tooth's contact, ``-spread … eps + spread`` (a pit or spall about the pitch point); at
#: -0.45 a loss of any gear pair with a contact ratio above 1 still lasts ``eps - 0.9 > 0.1``
#: cycles.
MIN_SPREAD = -0.45

_LOCATIONS = ("sun", "planet", "ring")
_FLANKS = ("sun", "ring", "both")


def _f64(x: ArrayLike) -> Float[Array, "..."]:
    return jnp.asarray(x, dtype=jnp.float64)


# --------------------------------------------------------------------------------------------
# Mesh phases
# --------------------------------------------------------------------------------------------


def mesh_phases(
    lp: LumpedParameters,
    theta_s: Float[ArrayLike, ""],
    theta_c: Float[ArrayLike, ""],
    theta_r: Float[ArrayLike, ""],
) -> tuple[Float[Array, " N"], Float[Array, " N"]]:
    r"""Mesh phases of every planet's sun and ring meshes (mesh cycles).

    .. math::

        \phi_{sp,i} = Z_s (\theta_s - \theta_c - \psi_i) / 2\pi + \phi_{0,sp}, \qquad
        \phi_{rp,i} = Z_r (\theta_c - \theta_r + \psi_i) / 2\pi + \phi_{0,rp}

    (docs/conventions.md, "Mesh phase"). Phase 0 (mod 1) is the start of double contact.

    **Arguments:** `lp` (lumped parameters: tooth numbers, planet angles ``psi_i`` (rad),
    ``phase0_sp``, ``phase0_rp`` (cycles)); absolute angles `theta_s`, `theta_c`, `theta_r` of
    sun, carrier and ring (rad), scalars.

    **Returns:** ``(phase_sp, phase_rp)``, each shape ``(N,)`` (cycles).
    """
    psi = lp.planet_angles
    ts, tc, tr = _f64(theta_s), _f64(theta_c), _f64(theta_r)
    phase_sp = lp.z_sun * (ts - tc - psi) / (2.0 * jnp.pi) + lp.phase0_sp
    phase_rp = lp.z_ring * (tc - tr + psi) / (2.0 * jnp.pi) + lp.phase0_rp
    return phase_sp, phase_rp


def planet_ring_delay(lp: LumpedParameters) -> Float[Array, ""]:
    r"""Mesh cycles from a planet tooth's entry into the sun mesh to its entry into the ring mesh.

    A planet tooth crosses the sun's line of centres (inner side) and, half a planet turn
    (``Zp/2`` cycles) later, the ring's (outer side). The sun loads the tooth's trailing flank
    and the ring its leading flank (in the carrier frame, power flows sun → planet → ring), so the
    contact on the two flanks is half a tooth thickness before and after the centreline:
    ``(delta + delta') Zp / 2pi = 1/2`` cycle for a standard tooth thickness of half the pitch.
    With the pitch point taken at mid-path of each contact (``eps/2`` cycles after entry):

    .. math:: D = \frac{Z_p - 1}{2} + \frac{\varepsilon_{sp} - \varepsilon_{rp}}{2}

    Only the integer part of the sun-to-ring offset is taken from this estimate (rounded in
    :func:`planet_tooth_phases`); the fractional part comes from ``phase0_rp - phase0_sp``,
    derived exactly from the tooth geometry in ``dtwin.model.gears``.

    **Returns:** ``D`` (mesh cycles).
    """
    return 0.5 * (lp.z_planet - 1) + 0.5 * (lp.eps_sp - lp.eps_rp)


def planet_tooth_phases(
    lp: LumpedParameters,
    theta_c: Float[ArrayLike, ""],
    theta_p: Float[ArrayLike, " N"],
) -> tuple[Float[Array, " N"], Float[Array, " N"]]:
    r"""Tooth counters of every planet on its sun and ring meshes, from the planet's own spin.

    .. math::

        q_{sp,i} &= -Z_p (\theta_{p,i} - \theta_c) / 2\pi - Z_s \psi_i / 2\pi + \phi_{0,sp} \\
        q_{rp,i} &= -Z_p (\theta_{p,i} - \theta_c) / 2\pi + Z_r \psi_i / 2\pi + \phi_{0,rp} - m_i,
        \quad m_i = \operatorname{round}\bigl((Z_s + Z_r)\psi_i/2\pi
                     + \phi_{0,rp} - \phi_{0,sp} + D\bigr)

    with ``D`` from :func:`planet_ring_delay`. Planet tooth ``k`` of planet ``i`` is in contact
    with the sun while ``(q_sp_i - k) mod Zp in [0, eps_sp)`` and with the ring while
    ``(q_rp_i - k) mod Zp in [0, eps_rp)``. The planet turns clockwise relative to the carrier
    (``theta_p - theta_c`` decreases), so the counters increase. Under rigid kinematics from the
    reference configuration (all angles zero, docs/conventions.md) ``q_sp_i = phase_sp_i`` and
    ``q_rp_i = phase_rp_i - m_i``, so the planet-tooth windows line up with each mesh's
    single/double contact zones; planet teeth are numbered by the sun-mesh count (tooth 0 starts
    its sun contact when ``q_sp_i = 0``).

    **Arguments:** `lp`; carrier angle `theta_c` (rad); absolute planet angles `theta_p`, shape
    ``(N,)`` (rad).

    **Returns:** ``(q_sp, q_rp)``, each shape ``(N,)`` (mesh cycles).
    """
    psi = lp.planet_angles
    spin = -lp.z_planet * (_f64(theta_p) - _f64(theta_c)) / (2.0 * jnp.pi)
    q_sp = spin - lp.z_sun * psi / (2.0 * jnp.pi) + lp.phase0_sp
    m = jnp.round(
        (lp.z_sun + lp.z_ring) * psi / (2.0 * jnp.pi) + lp.phase0_rp - lp.phase0_sp
        + planet_ring_delay(lp)
    )
    q_rp = spin + lp.z_ring * psi / (2.0 * jnp.pi) + lp.phase0_rp - jax.lax.stop_gradient(m)
    return q_sp, q_rp


# --------------------------------------------------------------------------------------------
# Windows and severity mapping
# --------------------------------------------------------------------------------------------


def _contact_time(x, period: int, eps):
    """Cycles since the tooth entered contact, wrapped to (eps/2 - P/2, eps/2 + P/2]."""
    half = 0.5 * period
    v = jnp.mod(x - 0.5 * eps + half, period) - half
    return v + 0.5 * eps


def _smooth_box(u, start, stop, edge=WINDOW_EDGE):
    return jax.nn.sigmoid((u - start) / edge) * jax.nn.sigmoid((stop - u) / edge)


def tooth_window(
    count: Float[ArrayLike, "..."], tooth: int, period: int, eps: Float[ArrayLike, ""]
) -> Float[Array, "..."]:
    r"""Smooth indicator (0…1) that tooth `tooth` is in contact: ``(count - tooth) mod period in [0, eps)``.

    .. math:: w = \sigma(u / e)\,\sigma((\varepsilon - u) / e),\quad e = \text{WINDOW\_EDGE}

    with ``u`` the cycles since the tooth entered contact, wrapped into one period centred on the
    contact interval. **Arguments:** `count` (mesh cycles: a mesh phase or a tooth counter),
    `tooth` (index), `period` (tooth count of the gear carrying the tooth), `eps` (contact
    ratio). **Returns:** window value, shape of `count`.
    """
    eps = _f64(eps)
    u = _contact_time(_f64(count) - tooth, period, eps)
    return _smooth_box(u, 0.0, eps)


def crack_loss_fraction(
    severity: Float[ArrayLike, "..."], w_bending: ArrayLike = 0.30, w_shear: ArrayLike = 0.09
) -> Float[Array, "..."]:
    r"""Fraction ``g`` of a tooth pair's stiffness lost to a root crack of relative depth `severity`.

    .. math:: g(s) = \frac{w_b (1 - u^3) + w_s (u^2 - u^3)}{u^3 (1 - w_b - w_s) + w_b + w_s u^2},
              \quad u = 1 - s

    (module docstring: cracked section thinned to ``h - q`` in the potential-energy beam model).
    **Arguments:** `severity` = crack depth / root thickness (1); `w_bending`, `w_shear`: shares of
    the healthy pair compliance from the cracked tooth's bending and shear+axial deformation.
    **Returns:** ``g`` in [0, 1]; ``g(0) = 0`` exactly, ``g(1) = 1``.
    """
    u = 1.0 - _f64(severity)
    wb, ws = _f64(w_bending), _f64(w_shear)
    u2 = u * u
    u3 = u2 * u
    return (wb * (1.0 - u3) + ws * (u2 - u3)) / (u3 * (1.0 - wb - ws) + wb + ws * u2)


# --------------------------------------------------------------------------------------------
# Faults
# --------------------------------------------------------------------------------------------


def _severity(x) -> Float[Array, ""]:
    return jnp.asarray(x, dtype=jnp.float64)


class AbstractFault(eqx.Module):
    """A local fault on one tooth, removing mesh stiffness while that tooth is in contact.

    Subclasses provide the fields `severity` (float64 scalar in [0, 1], a physical quantity
    named by the subclass), `location` (``"sun"``, ``"planet"``, ``"ring"``), `tooth` (index on
    that gear), `planet` (which planet, for planet faults), `flank` (``"sun"``, ``"ring"`` or
    ``"both"``: which meshes of a planet tooth are affected; ignored for sun and ring faults) and
    implement :meth:`loss_fraction`; the class variable `severity_meaning` says what
    `severity` measures.
    """

    severity_meaning: eqx.AbstractClassVar[str]
    severity: eqx.AbstractVar[Float[Array, ""]]
    location: eqx.AbstractVar[str]
    tooth: eqx.AbstractVar[int]
    planet: eqx.AbstractVar[int]
    flank: eqx.AbstractVar[str]
    ramp: eqx.AbstractVar[Float[Array, ""]]
    spread: eqx.AbstractVar[Float[Array, ""]]

    def __check_init__(self):
        if self.location not in _LOCATIONS:
            raise SpecError([("faults.location", f"must be one of {_LOCATIONS}, got "
                              f"{self.location!r}")])
        if self.flank not in _FLANKS:
            raise SpecError([("faults.flank", f"must be one of {_FLANKS}, got {self.flank!r}")])
        if int(self.tooth) != self.tooth or self.tooth < 0:
            raise SpecError([("faults.tooth", f"must be a tooth index >= 0, got {self.tooth!r}")])
        if int(self.planet) != self.planet or self.planet < 0:
            raise SpecError([("faults.planet", f"must be a planet index >= 0, got "
                              f"{self.planet!r}")])
        sev = self.severity
        if jnp.shape(sev) != ():
            raise SpecError([("faults.severity", f"must be a scalar, got shape {jnp.shape(sev)}")])
        if not isinstance(sev, jax.core.Tracer) and not (0.0 <= float(sev) <= 1.0):
            raise SpecError([("faults.severity", f"must lie in [0, 1] ({self.severity_meaning}), got "
                              f"{float(sev)}")])
        ramp = self.ramp
        if jnp.shape(ramp) != ():
            raise SpecError([("faults.ramp", f"must be a scalar, got shape {jnp.shape(ramp)}")])
        if not isinstance(ramp, jax.core.Tracer) and not (0.0 < float(ramp) <= MAX_RAMP):
            raise SpecError([("faults.ramp", f"the loss's rise and fall must take 0 < ramp <= "
                              f"{MAX_RAMP} mesh cycles, got {float(ramp)}")])
        spread = self.spread
        if jnp.shape(spread) != ():
            raise SpecError([("faults.spread", f"must be a scalar, got shape {jnp.shape(spread)}")])
        if not isinstance(spread, jax.core.Tracer) and not (MIN_SPREAD <= float(spread)
                                                             <= MAX_SPREAD):
            raise SpecError([("faults.spread", f"the loss may extend up to {MAX_SPREAD} mesh "
                              f"cycles beyond the contact, or be confined to its middle by up "
                              f"to {-MIN_SPREAD} cycles either side ({MIN_SPREAD} <= spread <= "
                              f"{MAX_SPREAD}), got {float(spread)}")])

    @abc.abstractmethod
    def loss_fraction(
        self, u: Float[Array, "..."], eps: Float[Array, ""]
    ) -> Float[Array, "..."]:
        """Fraction of the single-pair stiffness ``c'`` removed while the tooth is in contact.

        **Arguments:** `u`: cycles since the faulty tooth entered contact (``0 <= u < eps`` in
        contact); `eps`: contact ratio of that mesh. **Returns:** ``f(severity, u)`` (1); it is
        multiplied by the contact window and ``c'``; it must be exactly 0 when severity is 0.
        """

    def window(self, u: Float[Array, "..."], eps: Float[Array, ""]) -> Float[Array, "..."]:
        """The loss's window (0…1) at `u` cycles after the tooth entered contact: a smooth box
        from ``-spread`` to ``eps + spread`` with edges of width `ramp` (module docstring,
        "The loss's shape")."""
        return _smooth_box(u, -self.spread, eps + self.spread, self.ramp)

    def stiffness_loss(
        self,
        lp: LumpedParameters,
        theta_s: Float[ArrayLike, ""],
        theta_c: Float[ArrayLike, ""],
        theta_r: Float[ArrayLike, ""],
        theta_p: Float[ArrayLike, " N"],
    ) -> tuple[Float[Array, " N"], Float[Array, " N"]]:
        r"""Stiffness removed from each planet's sun and ring mesh (N/m), to be subtracted.

        .. math:: \Delta k_i = c' \, w(u_i) \, f(\text{severity}, u_i)

        **Arguments:** `lp` (lumped parameters); absolute angles `theta_s`, `theta_c`,
        `theta_r` (rad, scalars) and `theta_p` (rad, shape ``(N,)``).

        **Returns:** ``(dk_sp, dk_rp)``, each shape ``(N,)`` (N/m), non-negative.
        """
        n = lp.n_planets
        zeros = jnp.zeros((n,), dtype=jnp.float64)
        if self.location == "planet" and self.planet >= n:
            raise SpecError([("faults.planet", f"planet {self.planet} does not exist; the gear "
                              f"set has planets 0..{n - 1}")])
        z_gear = {"sun": lp.z_sun, "ring": lp.z_ring, "planet": lp.z_planet}[self.location]
        if self.tooth >= z_gear:
            raise SpecError([("faults.tooth", f"the {self.location} has teeth 0..{z_gear - 1}, "
                              f"got tooth {self.tooth}")])
        c_sp = single_pair_from_mean(lp.k_sun_planet, lp.eps_sp)
        c_rp = single_pair_from_mean(lp.k_ring_planet, lp.eps_rp)

        def loss(count, period, eps, c1):
            u = _contact_time(count - self.tooth, period, eps)
            return c1 * self.window(u, eps) * self.loss_fraction(u, eps)

        if self.location == "sun":
            phase_sp, _ = mesh_phases(lp, theta_s, theta_c, theta_r)
            return loss(phase_sp, lp.z_sun, lp.eps_sp, c_sp), zeros
        if self.location == "ring":
            _, phase_rp = mesh_phases(lp, theta_s, theta_c, theta_r)
            return zeros, loss(phase_rp, lp.z_ring, lp.eps_rp, c_rp)
        q_sp, q_rp = planet_tooth_phases(lp, theta_c, theta_p)
        mask = (jnp.arange(n) == self.planet).astype(jnp.float64)
        dk_sp = (mask * loss(q_sp, lp.z_planet, lp.eps_sp, c_sp)
                 if self.flank in ("sun", "both") else zeros)
        dk_rp = (mask * loss(q_rp, lp.z_planet, lp.eps_rp, c_rp)
                 if self.flank in ("ring", "both") else zeros)
        return dk_sp, dk_rp


class MissingTooth(AbstractFault):
    """Missing (broken-off) tooth; `severity` = fraction of the face width removed.

    ``f = severity`` over the whole contact of the tooth. On a planet it affects both meshes
    (`flank="both"`, default).
    """

    severity_meaning: ClassVar[str] = "missing tooth: fraction of the face width removed"
    severity: Float[Array, ""] = eqx.field(converter=_severity)
    location: str = eqx.field(static=True, default="sun")
    tooth: int = eqx.field(static=True, default=0)
    planet: int = eqx.field(static=True, default=0)
    flank: str = eqx.field(static=True, default="both")
    ramp: Float[Array, ""] = eqx.field(converter=_severity, default=WINDOW_EDGE)
    spread: Float[Array, ""] = eqx.field(converter=_severity, default=0.0)

    def loss_fraction(self, u, eps):
        return self.severity * jnp.ones_like(u)


class Pitting(AbstractFault):
    """Pitting on one flank; `severity` = fraction of the flank area in the pitting band lost.

    ``f = severity * band(u)``, the band a smooth box of the contact path from
    ``(band_centre - band_width/2) eps`` to ``(band_centre + band_width/2) eps`` mesh cycles after
    the tooth enters contact (default: 0.3 eps to 0.7 eps, around the pitch point). On a planet
    the default flank is the one meeting the sun (`flank="sun"`).
    """

    severity_meaning: ClassVar[str] = "pitting: fraction of the flank area in the pitting band lost"
    severity: Float[Array, ""] = eqx.field(converter=_severity)
    location: str = eqx.field(static=True, default="sun")
    tooth: int = eqx.field(static=True, default=0)
    planet: int = eqx.field(static=True, default=0)
    flank: str = eqx.field(static=True, default="sun")
    band_centre: float = eqx.field(static=True, default=0.5)
    band_width: float = eqx.field(static=True, default=0.4)
    ramp: Float[Array, ""] = eqx.field(converter=_severity, default=WINDOW_EDGE)
    spread: Float[Array, ""] = eqx.field(converter=_severity, default=0.0)

    def __check_init__(self):
        lo = self.band_centre - 0.5 * self.band_width
        hi = self.band_centre + 0.5 * self.band_width
        if not (self.band_width > 0.0 and lo >= 0.0 and hi <= 1.0):
            raise SpecError([("faults.band_width", f"the pitting band [{lo}, {hi}] (fractions of "
                              "the contact interval) must lie inside [0, 1] and have positive "
                              "width")])

    def loss_fraction(self, u, eps):
        lo = (self.band_centre - 0.5 * self.band_width) * eps
        hi = (self.band_centre + 0.5 * self.band_width) * eps
        return self.severity * _smooth_box(u, lo, hi)


class RootCrack(AbstractFault):
    """Root crack; `severity` = crack depth over tooth root thickness.

    ``f = g(severity)`` (:func:`crack_loss_fraction`) over the whole contact of the tooth. On a
    planet the default flank is the one meeting the sun; a crack weakens the whole tooth, so
    ``flank="both"`` is the physical choice when both meshes load it.
    """

    severity_meaning: ClassVar[str] = "root crack: crack depth over tooth root thickness"
    severity: Float[Array, ""] = eqx.field(converter=_severity)
    location: str = eqx.field(static=True, default="sun")
    tooth: int = eqx.field(static=True, default=0)
    planet: int = eqx.field(static=True, default=0)
    flank: str = eqx.field(static=True, default="both")
    w_bending: float = eqx.field(static=True, default=0.30)
    w_shear: float = eqx.field(static=True, default=0.09)
    ramp: Float[Array, ""] = eqx.field(converter=_severity, default=WINDOW_EDGE)
    spread: Float[Array, ""] = eqx.field(converter=_severity, default=0.0)

    def __check_init__(self):
        if not (self.w_bending > 0.0 and self.w_shear >= 0.0 and self.w_bending + self.w_shear < 1.0):
            raise SpecError([("faults.w_bending", "compliance shares need w_bending > 0, "
                              "w_shear >= 0 and w_bending + w_shear < 1")])

    def loss_fraction(self, u, eps):
        return crack_loss_fraction(self.severity, self.w_bending, self.w_shear) * jnp.ones_like(u)


_KINDS: dict[str, type[AbstractFault]] = {
    "missing_tooth": MissingTooth,
    "pitting": Pitting,
    "crack": RootCrack,
    "root_crack": RootCrack,
}


def make_fault(
    kind: str,
    location: str,
    severity: float | ArrayLike,
    *,
    tooth: int = 0,
    planet: int = 0,
    flank: str | None = None,
) -> AbstractFault:
    """Build a fault by name (for spec files and the CLI).

    **Arguments:** `kind` (``missing_tooth``, ``pitting``, ``crack``/``root_crack``), `location`
    (``sun``, ``planet``, ``ring``), `severity` (1, in [0, 1]), `tooth` index, `planet` index,
    `flank` (None: the fault type's default). **Returns:** the fault.
    """
    try:
        cls = _KINDS[kind]
    except KeyError:
        raise SpecError([("faults.kind", f"unknown fault kind {kind!r}; use one of "
                          f"{sorted(_KINDS)}")]) from None
    kwargs = {} if flank is None else {"flank": flank}
    return cls(severity, location=location, tooth=tooth, planet=planet, **kwargs)


def faults_from_table(entries: Sequence[Mapping[str, Any]]) -> tuple[AbstractFault, ...]:
    """Faults from a spec's ``[[faults]]`` tables (keys ``type``, ``location``, ``severity``,
    optional ``tooth``, ``planet``, ``flank``; :data:`dtwin.spec.FAULT_SCHEMA`).

    **Returns:** a tuple of faults, in the order given (empty for no entries).
    """
    out = []
    for i, e in enumerate(entries):
        try:
            kind, location, severity = e["type"], e["location"], e["severity"]
        except KeyError as err:
            raise SpecError([(f"faults[{i}].{err.args[0]}", "is required")]) from None
        out.append(make_fault(kind, location, severity, tooth=int(e.get("tooth", 0)),
                              planet=int(e.get("planet", 0)), flank=e.get("flank")))
    return tuple(out)


def parse_fault(text: str) -> AbstractFault:
    """Parse ``LOCATION:KIND:SEVERITY[:TOOTH[:PLANET[:FLANK]]]``, e.g. ``sun:missing_tooth:0.5``
    or ``planet:pitting:0.3:4:1:sun`` (the CLI's ``--fault``)."""
    parts = text.split(":")
    if not 3 <= len(parts) <= 6:
        raise SpecError([("--fault", f"expected LOCATION:KIND:SEVERITY[:TOOTH[:PLANET[:FLANK]]], "
                          f"e.g. sun:missing_tooth:0.5, got {text!r}")])
    location, kind, sev = parts[:3]
    try:
        severity = float(sev)
        tooth = int(parts[3]) if len(parts) > 3 else 0
        planet = int(parts[4]) if len(parts) > 4 else 0
    except ValueError:
        raise SpecError([("--fault", f"severity must be a number and tooth/planet integers in "
                          f"{text!r}")]) from None
    flank = parts[5] if len(parts) > 5 else None
    return make_fault(kind, location, severity, tooth=tooth, planet=planet, flank=flank)


def total_stiffness_loss(
    faults: Sequence[AbstractFault],
    lp: LumpedParameters,
    theta_s: Float[ArrayLike, ""],
    theta_c: Float[ArrayLike, ""],
    theta_r: Float[ArrayLike, ""],
    theta_p: Float[ArrayLike, " N"],
) -> tuple[Float[Array, " N"], Float[Array, " N"]]:
    """Sum of :meth:`AbstractFault.stiffness_loss` over several faults (combined faults), N/m.

    **Returns:** ``(dk_sp, dk_rp)``, each shape ``(N,)``; zeros for no faults.
    """
    dk_sp = jnp.zeros((lp.n_planets,), dtype=jnp.float64)
    dk_rp = jnp.zeros((lp.n_planets,), dtype=jnp.float64)
    for f in faults:
        a, b = f.stiffness_loss(lp, theta_s, theta_c, theta_r, theta_p)
        dk_sp = dk_sp + a
        dk_rp = dk_rp + b
    return dk_sp, dk_rp


def mesh_stiffnesses(
    lp: LumpedParameters,
    theta_s: Float[ArrayLike, ""],
    theta_c: Float[ArrayLike, ""],
    theta_r: Float[ArrayLike, ""],
    theta_p: Float[ArrayLike, " N"],
    faults: Sequence[AbstractFault] = (),
    *,
    n_harmonics: int = 12,
) -> tuple[Float[Array, " N"], Float[Array, " N"]]:
    """Time-varying stiffness of every planet's sun and ring mesh, faults included (N/m).

    ``k_sp_i = waveform(phase_sp_i; k_sun_planet, eps_sp) - dk_sp_i`` and likewise for the ring
    (:func:`dtwin.model.stiffness.mesh_stiffness_waveform`, :func:`total_stiffness_loss`), floored at
    0 (a fault that removes a whole pair in single contact leaves no stiffness). Without faults,
    or with every severity 0, the healthy waveform is returned bit for bit.

    **Returns:** ``(k_sp, k_rp)``, each shape ``(N,)`` (N/m).
    """
    phase_sp, phase_rp = mesh_phases(lp, theta_s, theta_c, theta_r)
    k_sp = mesh_stiffness_waveform(phase_sp, lp.k_sun_planet, lp.eps_sp, n_harmonics=n_harmonics)
    k_rp = mesh_stiffness_waveform(phase_rp, lp.k_ring_planet, lp.eps_rp, n_harmonics=n_harmonics)
    if not faults:
        return k_sp, k_rp
    dk_sp, dk_rp = total_stiffness_loss(faults, lp, theta_s, theta_c, theta_r, theta_p)
    # The band-limited healthy wave and the sigmoid windows do not share their edges exactly,
    # so a fault removing a whole pair can undershoot zero by ~1 % of c' in single contact; a
    # mesh cannot have negative stiffness, hence the floor (exact, and inactive for k - dk > 0,
    # so severity 0 still returns the healthy wave bit for bit).
    return jnp.maximum(k_sp - dk_sp, 0.0), jnp.maximum(k_rp - dk_rp, 0.0)



# --------------------------------------------------------------------------------------------
# Severity in physical terms: the peak mesh-stiffness loss
# --------------------------------------------------------------------------------------------


def _contact_ratio(fault: AbstractFault, lp_or_eps) -> Float[Array, ""]:
    """Contact ratio of the mesh the fault's tooth loads (sun mesh for sun faults and planet
    faults on the sun flank, ring mesh otherwise; a float is taken as the contact ratio)."""
    if isinstance(lp_or_eps, LumpedParameters):
        ring = fault.location == "ring" or (fault.location == "planet" and fault.flank == "ring")
        return _f64(lp_or_eps.eps_rp if ring else lp_or_eps.eps_sp)
    return _f64(lp_or_eps)


#: Healthy mesh stiffness a loss is taken relative to (:func:`stiffness_loss_profile`), in
#: units of the single-pair stiffness ``c'`` of the ISO 6336 waveform.
REFERENCES = ("instant", "mean", "max", "min")


def _healthy(reference: str, u, eps):
    """Healthy stiffness (units of ``c'``) at `u` for `reference` (:data:`REFERENCES`)."""
    if reference == "instant":
        return jnp.where(jnp.mod(u, 1.0) < eps - 1.0, 1.0 + 0.75, 1.0)
    if reference == "mean":
        return (0.75 * eps + 0.25) * jnp.ones_like(u)
    if reference == "max":
        return 1.75 * jnp.ones_like(u)
    if reference == "min":
        return jnp.ones_like(u)
    raise SpecError([("reference", f"must be one of {REFERENCES}, got {reference!r}")])


def stiffness_loss_profile(
    fault: AbstractFault, lp_or_eps, u: Float[ArrayLike, " n"], reference: str = "instant"
) -> Float[Array, " n"]:
    r"""Fractional drop of the mesh stiffness at `u` mesh cycles after the faulty tooth enters
    contact, relative to the healthy mesh stiffness there.

    .. math:: \frac{\Delta k(u)}{k_{healthy}(u)} = \frac{w(u)\, f(\text{severity}, u)}
              {1 + 0.75\,[\operatorname{frac}(u) < \varepsilon - 1]}

    with ``w`` the fault's smooth window (:meth:`AbstractFault.window`: edges of width
    `fault.ramp`, `fault.spread` beyond the contact), ``f`` its
    :meth:`AbstractFault.loss_fraction` and the healthy stiffness the ideal ISO 6336 waveform in
    units of ``c'``: ``1.75`` in double contact, ``1`` in single contact (the tooth enters at the
    start of a double-contact zone, docs/conventions.md).

    `reference` (:data:`REFERENCES`) chooses the healthy stiffness: ``instant`` (the formula
    above), ``mean`` (the mean mesh stiffness ``c_γ = (0.75 ε + 0.25) c'``, ISO 6336-1: a
    reference that does not depend on the waveform's shape), ``max`` (``1.75 c'``, the
    waveform's largest value) or ``min`` (``c'``, its smallest). Any healthy waveform between
    the single-pair and double-contact values gives a fraction between the ``max`` and ``min``
    ones.

    **Arguments:** `fault`; `lp_or_eps`: the gear set's :class:`LumpedParameters` (the contact
    ratio of the fault's mesh is taken from it) or that contact ratio; `u` (mesh cycles);
    `reference`. **Returns:** the fractional loss (1) at each `u`.
    """
    eps = _contact_ratio(fault, lp_or_eps)
    u = _f64(u)
    return fault.window(u, eps) * fault.loss_fraction(u, eps) / _healthy(reference, u, eps)


def peak_stiffness_loss(fault: AbstractFault, lp_or_eps, n_grid: int = 2001,
                        reference: str = "instant") -> Float[Array, ""]:
    r"""Peak mesh-stiffness loss of a fault: the largest fractional drop of the mesh stiffness
    while the faulty tooth is in mesh (:func:`stiffness_loss_profile`, maximised over the tooth's
    passage, ``-4 ramp - spread … eps + spread + 4 ramp`` cycles on `n_grid` points).

    The quantity comparable across fault models, benches and twins: severity is what a fault
    type's own geometry measures (face width removed, pitted area, crack depth), the peak loss
    what the mesh feels. A missing tooth of severity ``s`` with a sharp ramp has peak loss ``s``
    (the whole pair, in single contact, where the healthy mesh has ``c'``); a root crack
    ``g(s)`` (:func:`crack_loss_fraction`); a wide `ramp` lowers the peak of a short contact.
    With ``reference="mean"`` the loss is taken relative to the mean mesh stiffness instead
    (``s / (0.75 ε + 0.25)`` for the sharp missing tooth). Differentiable in the severity and
    the ramp.

    **Arguments:** `fault`; `lp_or_eps` (lumped parameters or the contact ratio of the fault's
    mesh); `n_grid`; `reference` (:func:`stiffness_loss_profile`). **Returns:** peak loss (1, a
    fraction; × 100 for %).
    """
    eps = _contact_ratio(fault, lp_or_eps)
    s = jnp.linspace(0.0, 1.0, n_grid, dtype=jnp.float64)
    u = -4.0 * fault.ramp - fault.spread + s * (eps + 8.0 * fault.ramp + 2.0 * fault.spread)
    return jnp.max(stiffness_loss_profile(fault, eps, u, reference))


def severity_for_peak_loss(fault: AbstractFault, lp_or_eps, peak: float) -> float:
    """Inverse of :func:`peak_stiffness_loss`: the severity of a fault of `fault`'s type, place
    and ramp whose peak mesh-stiffness loss is `peak` (bisection; the loss grows with the
    severity). **Returns:** severity in [0, 1]; 1 when even severity 1 loses less than `peak`.
    """
    def at(s):
        return float(peak_stiffness_loss(eqx.tree_at(lambda f: f.severity, fault,
                                                     jnp.asarray(s, jnp.float64)), lp_or_eps))

    if peak <= 0.0:
        return 0.0
    if at(1.0) <= peak:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if at(mid) < peak else (lo, mid)
    return 0.5 * (lo + hi)
