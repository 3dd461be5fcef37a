"""Geometry, kinematics, mesh phasing and characteristic frequencies of a planetary gear set.

One stage: sun (input), ring (fixed), carrier (output), `N` planets. Frames, angles and the
numbering of planets follow ``docs/conventions.md``; all quantities are SI (m, kg, kg·m², rad, Hz).

Tooth geometry is the ISO 53 basic rack (addendum ``1·m``, dedendum ``1.25·m``), involute spur
gears, no tip shortening. Profile shifts ``x`` are in modules; for the internal ring gear a
positive ``x_ring`` moves its profile away from the gear centre (the tooth *space* at the
reference circle is ``m (π/2 + 2 x_ring tan α)`` wide), which is the sign that makes the
zero-backlash condition of the ring–planet mesh read (ISO 21771 / DIN 3960, which sign internal
gears' tooth counts negative, count the shift positive towards the tips: ``x_ISO = −x_ring``)

    inv α_w,rp = inv α + 2 tan α (x_r − x_p) / (z_r − z_p)            (internal mesh)
    inv α_w,sp = inv α + 2 tan α (x_s + x_p) / (z_s + z_p)            (external mesh)

Both meshes share the carrier radius ``a`` (the operating centre distance), so

    a = m (z_s + z_p) cos α / (2 cos α_w,sp) = m (z_r − z_p) cos α / (2 cos α_w,rp).

**Rule for a centre distance given without shifts** (and for a gear set given with neither):
the planet stays standard (``x_planet = 0``), the sun takes the whole shift sum of the
sun–planet mesh and the ring the whole shift difference of the ring–planet mesh. With neither a
centre distance nor shifts, ``a`` is the mean of the two standard centre distances
``(m (z_s + z_p)/2 + m (z_r − z_p)/2) / 2`` (equal for a standard set ``z_r = z_s + 2 z_p``;
52.5 mm for the paper's bench 21/31/84, m = 2 mm).

Reference: Parker & Lin (2004), "Mesh phasing relationships in planetary and epicyclic gears",
J. Mech. Des. 126:365; ISO 21771 (cylindrical gears: concepts and geometry).
"""

from __future__ import annotations

import math
import warnings
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..errors import GeometryError
from .kinematics import Kinematics

STEEL_DENSITY = 7850.0
"""Density of steel (kg/m³) used for masses from geometry unless a spec gives another."""

ADDENDUM = 1.0
"""Addendum coefficient h_a* of the basic rack (ISO 53), in modules."""

DEDENDUM = 1.25
"""Dedendum coefficient h_f* of the basic rack (ISO 53), in modules."""

RING_RIM = 3.0
"""Ring rim thickness below the tooth roots, in modules (assumption for masses)."""


def involute(alpha: ArrayLike) -> Float[Array, "..."]:
    """The involute function ``inv α = tan α − α``.

    **Arguments:** `alpha`: pressure angle (rad).

    **Returns:** ``inv α`` (rad).
    """
    alpha = jnp.asarray(alpha, dtype=jnp.float64)
    return jnp.tan(alpha) - alpha


def inverse_involute(inv: ArrayLike) -> Float[Array, "..."]:
    """Solve ``tan α − α = inv`` for ``α`` in (0, π/2) (Newton, 30 iterations, jittable).

    The start value ``α0 = (3 inv)^(1/3)`` is the first term of the series of the inverse; the
    Newton step is ``Δα = (inv α − inv) / tan² α``.

    **Arguments:** `inv`: value of the involute function (rad), positive.

    **Returns:** ``α`` (rad).
    """
    inv = jnp.asarray(inv, dtype=jnp.float64)
    a0 = jnp.cbrt(3.0 * inv) / (1.0 + 0.2 * jnp.cbrt(3.0 * inv) ** 2)

    def body(_, a):
        t = jnp.tan(a)
        return a - (t - a - inv) / (t * t)

    return jax.lax.fori_loop(0, 30, body, a0)


def _f64(x: ArrayLike) -> Float[Array, ""]:
    return jnp.asarray(x, dtype=jnp.float64)


class GearSet(eqx.Module):
    """A single-stage planetary gear set (involute spur gears, ring fixed, sun in, carrier out).

    **Fields** (all SI):

    - `z_sun`, `z_planet`, `z_ring`, `n_planets`: tooth counts and number of planets (static).
    - `module`: normal module m (m), e.g. 0.002.
    - `pressure_angle`: reference pressure angle α (rad), e.g. 20° = 0.349 rad.
    - `face_width`: face width b (m).
    - `x_sun`, `x_planet`, `x_ring`: profile shift coefficients (in modules; ring sign as in the
      module docstring).
    - `centre_distance`: operating centre distance a = carrier radius (m).
    - `planet_angles`: carrier-frame angles ψ_i of the planets (rad), planet 0 on +x.

    Construct with keyword arguments; `x_*` and `centre_distance` may be left out (``None``):
    a centre distance without shifts is realised by shifts with the rule of the module
    docstring, shifts without a centre distance give the centre distance (both meshes must
    agree), neither gives the mean of the two standard centre distances. `planet_angles`
    defaults to equal spacing ``2π i/N``.

    Raises `GeometryError` (naming the spec field) for non-positive tooth counts, ``N < 1``,
    planets whose tip circles overlap (``2 a sin(π/N) ≤ d_a,planet``), shifts that do not give one
    carrier radius, contact ratios below 1 and non-positive dimensions. Warns (does not refuse)
    when ``(z_s + z_r)/N`` is not an integer (equally spaced planets cannot be assembled) and when
    ``z_r ≠ z_s + 2 z_p`` (profile shift needed, as on the paper's bench 21/31/84).

    Construction is a boundary operation (concrete values, checks); every function of a built
    gear set below is pure JAX, jittable and differentiable — replace a field with
    ``eqx.tree_at`` to differentiate with respect to it.
    """

    z_sun: int = eqx.field(static=True)
    z_planet: int = eqx.field(static=True)
    z_ring: int = eqx.field(static=True)
    n_planets: int = eqx.field(static=True)
    module: Float[Array, ""]
    pressure_angle: Float[Array, ""]
    face_width: Float[Array, ""]
    x_sun: Float[Array, ""]
    x_planet: Float[Array, ""]
    x_ring: Float[Array, ""]
    centre_distance: Float[Array, ""]
    planet_angles: Float[Array, " N"]

    def __init__(
        self,
        *,
        z_sun: int,
        z_planet: int,
        z_ring: int,
        n_planets: int,
        module: float,
        face_width: float,
        pressure_angle: float = math.radians(20.0),
        x_sun: float | None = None,
        x_planet: float | None = None,
        x_ring: float | None = None,
        centre_distance: float | None = None,
        planet_angles: ArrayLike | None = None,
    ):
        problems: list[tuple[str, str]] = []
        for name, z in (("z_sun", z_sun), ("z_planet", z_planet), ("z_ring", z_ring)):
            if int(z) != z or z <= 0:
                problems.append((f"gears.{name}", f"must be a positive integer, got {z!r}"))
        if int(n_planets) != n_planets or n_planets < 1:
            problems.append(("gears.n_planets", f"must be an integer >= 1, got {n_planets!r}"))
        for name, v in (("module", module), ("face_width", face_width)):
            if not (np.isfinite(v) and v > 0):
                problems.append((f"gears.{name}", f"must be positive (m), got {v!r}"))
        if not (0.0 < pressure_angle < math.radians(45.0)):
            hint = (f": did you mean {pressure_angle:g}° = {math.radians(pressure_angle):.6g} rad?"
                    if 0.0 < math.radians(pressure_angle) < math.radians(45.0) else "")
            problems.append(
                ("gears.pressure_angle", f"must lie in (0, 0.785) rad, got {pressure_angle!r}"
                 f"{hint}")
            )
        if problems:
            raise GeometryError(problems)
        zs, zp, zr, n = int(z_sun), int(z_planet), int(z_ring), int(n_planets)
        if zr <= zp + 2:
            raise GeometryError(
                [("gears.z_ring", f"the ring needs more teeth than the planet + 2; got z_ring={zr},"
                  f" z_planet={zp}")]
            )
        m, alpha = float(module), float(pressure_angle)
        a_sp0 = m * (zs + zp) / 2.0
        a_rp0 = m * (zr - zp) / 2.0
        inv_a = math.tan(alpha) - alpha
        shifts_given = any(v is not None for v in (x_sun, x_planet, x_ring))

        def inv_w(a: float, a0: float, field: str) -> float:
            c = a0 * math.cos(alpha) / a
            if not (0.0 < c < 1.0):
                raise GeometryError(
                    [(field, f"centre distance {a:.6g} m cannot be realised from the standard "
                      f"{a0:.6g} m (cos α_w = {c:.4g})")]
                )
            aw = math.acos(c)
            return math.tan(aw) - aw

        def a_from_inv(inv: float, a0: float) -> float:
            aw = float(inverse_involute(inv))
            return a0 * math.cos(alpha) / math.cos(aw)

        if centre_distance is None and not shifts_given:
            centre_distance = 0.5 * (a_sp0 + a_rp0)
            if zr != zs + 2 * zp:  # dtwin chose the centre distance: say so, and how to state it
                warnings.warn(
                    f"z_ring = {zr} != z_sun + 2 z_planet = {zs + 2 * zp}: the set needs profile "
                    f"shift; with neither gears.centre_distance nor the shifts given, dtwin takes "
                    f"a = {centre_distance * 1e3:.4f} mm (the mean of the standard centre "
                    "distances) with x_planet = 0; give gears.centre_distance (or x_sun, "
                    "x_planet, x_ring) to state your gearbox's", stacklevel=2)
        if centre_distance is not None and not (np.isfinite(centre_distance)
                                                and centre_distance > 0):
            raise GeometryError(
                [("gears.centre_distance", f"must be positive (m), got {centre_distance!r}")]
            )
        if centre_distance is not None and not shifts_given:
            a = float(centre_distance)
            sum_sp = (inv_w(a, a_sp0, "gears.centre_distance") - inv_a) * (zs + zp) / (
                2 * math.tan(alpha))
            diff_rp = (inv_w(a, a_rp0, "gears.centre_distance") - inv_a) * (zr - zp) / (
                2 * math.tan(alpha))
            xs, xp, xr = sum_sp, 0.0, diff_rp
        else:
            xs = 0.0 if x_sun is None else float(x_sun)
            xp = 0.0 if x_planet is None else float(x_planet)
            xr = 0.0 if x_ring is None else float(x_ring)
            inv_sp = inv_a + 2 * math.tan(alpha) * (xs + xp) / (zs + zp)
            inv_rp = inv_a + 2 * math.tan(alpha) * (xr - xp) / (zr - zp)
            if inv_sp <= 0 or inv_rp <= 0:
                raise GeometryError(
                    [("gears.x_sun" if inv_sp <= 0 else "gears.x_ring",
                      "profile shifts give a non-positive operating pressure angle")]
                )
            a_sp, a_rp = a_from_inv(inv_sp, a_sp0), a_from_inv(inv_rp, a_rp0)
            tol = 1e-3 * m
            if centre_distance is None:
                if abs(a_sp - a_rp) > tol:
                    need_xr = xp + (inv_w(a_sp, a_rp0, "gears.x_ring") - inv_a) * (zr - zp) / (
                        2 * math.tan(alpha))
                    raise GeometryError(
                        [("gears.x_ring",
                          f"the shifts give the sun-planet mesh a = {a_sp * 1e3:.4f} mm but the "
                          f"ring-planet mesh a = {a_rp * 1e3:.4f} mm: one carrier radius is "
                          f"needed. Set x_ring = {need_xr:.4f} or give gears.centre_distance "
                          "without shifts")]
                    )
                centre_distance = 0.5 * (a_sp + a_rp)
            else:
                a = float(centre_distance)
                for field, am in (("gears.x_sun", a_sp), ("gears.x_ring", a_rp)):
                    if abs(am - a) > tol:
                        raise GeometryError(
                            [(field, f"the profile shifts give a = {am * 1e3:.4f} mm for this mesh"
                              f" but gears.centre_distance = {a * 1e3:.4f} mm; give only one of "
                              "them (shifts or centre distance) or make them agree")]
                        )
        a = float(centre_distance)

        if planet_angles is None:
            psi = 2.0 * np.pi * np.arange(n) / n
        else:
            psi = np.asarray(planet_angles, dtype=np.float64).reshape(-1)
            if psi.shape != (n,) or not np.all(np.isfinite(psi)):
                raise GeometryError(
                    [("gears.planet_angles", f"needs {n} finite angles (rad), got {psi.tolist()}")]
                )

        self.z_sun, self.z_planet, self.z_ring, self.n_planets = zs, zp, zr, n
        self.module = _f64(m)
        self.pressure_angle = _f64(alpha)
        self.face_width = _f64(float(face_width))
        self.x_sun, self.x_planet, self.x_ring = _f64(xs), _f64(xp), _f64(xr)
        self.centre_distance = _f64(a)
        self.planet_angles = jnp.asarray(psi, dtype=jnp.float64)

    def __check_init__(self):
        if isinstance(self.centre_distance, jax.core.Tracer):
            return  # built inside a transformation: checked where it was built concretely
        problems: list[tuple[str, str]] = []
        a = float(self.centre_distance)
        n = self.n_planets
        d_tip = 2.0 * float(tip_radii(self)[1])
        if n > 1:
            # the closest pair of planet centres (for equal spacing 2 a sin(π/N))
            psi = np.sort(np.mod(np.asarray(self.planet_angles), 2 * np.pi))
            gaps = np.diff(np.concatenate([psi, psi[:1] + 2 * np.pi]))
            chord = 2.0 * a * np.sin(np.min(gaps) / 2.0)
            if chord <= d_tip:
                problems.append(
                    ("gears.n_planets",
                     f"{n} planets do not fit: neighbouring planet centres are "
                     f"{chord * 1e3:.2f} mm apart (2 a sin(π/N)), less than the planet tip "
                     f"diameter {d_tip * 1e3:.2f} mm; use fewer planets or a smaller planet")
                )
        ra = tip_radii(self)
        rb = base_radii(self)
        if float(ra[2]) <= float(rb[2]):
            problems.append(("gears.x_ring", "the ring's tip circle lies inside its base circle "
                             "(no involute flank); reduce the negative ring shift"))
        for name, r in (("x_sun", root_radii(self)[0]), ("x_planet", root_radii(self)[1])):
            if float(r) <= 0:
                problems.append((f"gears.{name}", "the root circle radius is not positive"))
        eps_sp, eps_rp = contact_ratios(self)
        for name, eps in (("sun-planet", eps_sp), ("ring-planet", eps_rp)):
            if not float(eps) >= 1.0:
                problems.append(
                    ("gears", f"the {name} transverse contact ratio is {float(eps):.3f} < 1: the "
                     "teeth lose contact; check the shifts / centre distance")
                )
        if problems:
            raise GeometryError(problems)
        if (self.z_sun + self.z_ring) % n != 0:
            warnings.warn(
                f"(z_sun + z_ring)/n_planets = {(self.z_sun + self.z_ring) / n:.3f} is not an "
                "integer: equally spaced planets cannot be assembled", stacklevel=3)

    @property
    def gear_ratio(self) -> float:
        """Sun-to-carrier speed ratio with the ring fixed, ``1 + z_r/z_s``."""
        return 1.0 + self.z_ring / self.z_sun


# --- radii -------------------------------------------------------------------------------------


def reference_radii(gs: GearSet) -> Float[Array, "3"]:
    """Reference (pitch) radii ``r = m z / 2`` of sun, planet, ring (m)."""
    z = jnp.asarray([gs.z_sun, gs.z_planet, gs.z_ring], dtype=jnp.float64)
    return gs.module * z / 2.0


def base_radii(gs: GearSet) -> Float[Array, "3"]:
    """Base radii ``r_b = r cos α`` of sun, planet, ring (m); independent of profile shift."""
    return reference_radii(gs) * jnp.cos(gs.pressure_angle)


def tip_radii(gs: GearSet) -> Float[Array, "3"]:
    """Tip radii of sun, planet, ring (m).

    External: ``r_a = r + m (h_a* + x)``; internal ring: ``r_a = r − m (h_a* − x_r)`` (its tips
    point inwards). No tip shortening.
    """
    r = reference_radii(gs)
    m = gs.module
    return jnp.stack([
        r[0] + m * (ADDENDUM + gs.x_sun),
        r[1] + m * (ADDENDUM + gs.x_planet),
        r[2] - m * (ADDENDUM - gs.x_ring),
    ])


def root_radii(gs: GearSet) -> Float[Array, "3"]:
    """Root radii of sun, planet, ring (m).

    External: ``r_f = r − m (h_f* − x)``; internal ring: ``r_f = r + m (h_f* + x_r)``.
    """
    r = reference_radii(gs)
    m = gs.module
    return jnp.stack([
        r[0] - m * (DEDENDUM - gs.x_sun),
        r[1] - m * (DEDENDUM - gs.x_planet),
        r[2] + m * (DEDENDUM + gs.x_ring),
    ])


def base_pitch(gs: GearSet) -> Float[Array, ""]:
    """Transverse base pitch ``p_b = π m cos α`` (m), the same on both meshes."""
    return jnp.pi * gs.module * jnp.cos(gs.pressure_angle)


def operating_pressure_angles(gs: GearSet) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Operating pressure angles ``(α_sp, α_rp)`` (rad) at the centre distance ``a``.

    ``cos α_w,sp = m (z_s + z_p) cos α / (2 a)``, ``cos α_w,rp = m (z_r − z_p) cos α / (2 a)``,
    i.e. ``r_b,s + r_b,p = a cos α_sp`` and ``r_b,r − r_b,p = a cos α_rp``.
    """
    rb = base_radii(gs)
    a = gs.centre_distance
    return jnp.arccos((rb[0] + rb[1]) / a), jnp.arccos((rb[2] - rb[1]) / a)


def working_radii(gs: GearSet) -> dict[str, Float[Array, ""]]:
    """Operating pitch radii (m): ``sun``, ``planet_sp`` (planet on the sun mesh), ``planet_rp``
    (planet on the ring mesh) and ``ring``; ``r_w = r_b / cos α_w``."""
    rb = base_radii(gs)
    a_sp, a_rp = operating_pressure_angles(gs)
    return {
        "sun": rb[0] / jnp.cos(a_sp),
        "planet_sp": rb[1] / jnp.cos(a_sp),
        "planet_rp": rb[1] / jnp.cos(a_rp),
        "ring": rb[2] / jnp.cos(a_rp),
    }


def _tip_tangents(gs: GearSet) -> Float[Array, "3"]:
    """Length ``sqrt(r_a² − r_b²)`` from each base-circle tangent point to its tip circle (m)."""
    ra, rb = tip_radii(gs), base_radii(gs)
    return jnp.sqrt(ra * ra - rb * rb)


def contact_ratios(gs: GearSet) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Transverse contact ratios ``(ε_sp, ε_rp)`` from the involute geometry.

    External (sun–planet): ``ε = (√(r_a,s² − r_b,s²) + √(r_a,p² − r_b,p²) − a sin α_w) / p_b``;
    internal (ring–planet): ``ε = (√(r_a,p² − r_b,p²) − √(r_a,r² − r_b,r²) + a sin α_w) / p_b``.
    Reference: ISO 21771 §5.4 / any gear text (e.g. Niemann–Winter).
    """
    t = _tip_tangents(gs)
    pb = base_pitch(gs)
    a_sp, a_rp = operating_pressure_angles(gs)
    a = gs.centre_distance
    return (t[0] + t[1] - a * jnp.sin(a_sp)) / pb, (t[1] - t[2] + a * jnp.sin(a_rp)) / pb


# --- mesh phasing -----------------------------------------------------------------------------


def relative_mesh_phase(gs: GearSet) -> Float[Array, ""]:
    """Phase of a planet's ring mesh relative to its sun mesh, ``phase0_rp − phase0_sp`` (cycles).

    Derivation (planet at ψ = 0, carrier frame; phase 0 = a new pair enters contact). The sun
    drives the planet's flanks that trail in its (clockwise, relative to the carrier) spin; the
    planet drives the ring with its leading flanks. Along the sun-mesh line of action (from the
    sun's tangent point T1 to the planet's T2, length ``a sin α_sp``) a pair enters contact at the
    planet's tip, at distance ``D_p = √(r_a,p² − r_b,p²)`` from T2; along the ring-mesh line
    (from the ring's tangent point T4; the planet's T3 lies at ``a sin α_rp``) a pair enters at the
    ring's tip, ``D_r = √(r_a,r² − r_b,r²)`` from T4. A trailing flank whose base point lies at
    planet angle φ cuts the first line ``r_b,p (φ − (π − α_sp))`` from T2, a leading flank at
    ``φ − 2ψ_b`` cuts the second ``r_b,p (α_rp − φ + 2ψ_b)`` beyond T3, ``ψ_b = s_p/(2 r_p) + inv α``
    the half tooth-thickness angle at the base circle. Both counted in base pitches
    ``p_b = 2π r_b,p / z_p``, the planet angle cancels:

        Δ = [a sin α_rp − D_r − D_p + r_b,p (α_sp + α_rp + 2 ψ_b − π)] / p_b   (mod 1)

    The ``−z_p/2`` inside ``r_b,p π / p_b`` is where the parity of ``z_p`` enters (half a cycle
    between an even and an odd planet); ``2 ψ_b z_p/2π = 1/2 + (2 x_p tan α + z_p inv α)/π``.

    The phase is that of the loaded flanks with the sun driving (input torque CCW, as in
    docs/conventions.md); with the torque reversed the other flanks mesh and Δ changes.
    ``tests/test_gears.py`` checks it against an independent flank-contact calculation.

    Reference: Parker & Lin (2004), J. Mech. Des. 126:365 (mesh phasing from the contact-line
    positions and the planet tooth count).

    **Returns:** Δ in [0, 1) (mesh cycles).
    """
    rb = base_radii(gs)
    t = _tip_tangents(gs)
    a_sp, a_rp = operating_pressure_angles(gs)
    alpha = gs.pressure_angle
    s_p = gs.module * (jnp.pi / 2.0 + 2.0 * gs.x_planet * jnp.tan(alpha))
    psi_b = s_p / (2.0 * reference_radii(gs)[1]) + involute(alpha)
    num = (gs.centre_distance * jnp.sin(a_rp) - t[2] - t[1]
           + rb[1] * (a_sp + a_rp + 2.0 * psi_b - jnp.pi))
    return jnp.mod(num / base_pitch(gs), 1.0)


class MeshPhasing(eqx.Module):
    """Mesh phasing of all planets (cycles; docs/conventions.md, "Mesh phase").

    - `gamma_sp`: ``Zs ψ_i / 2π mod 1``, lag of planet i's sun mesh behind planet 0's.
    - `gamma_rp`: ``−Zr ψ_i / 2π mod 1``, planet i's ring mesh relative to planet 0's.
    - `phase0_sp`: 0 by convention (the sun's angle origin is chosen so that planet 0's sun mesh
      starts a new tooth pair at t = 0).
    - `phase0_rp`: :func:`relative_mesh_phase`.
    """

    gamma_sp: Float[Array, " N"]
    gamma_rp: Float[Array, " N"]
    phase0_sp: Float[Array, ""]
    phase0_rp: Float[Array, ""]


def mesh_phasing(gs: GearSet) -> MeshPhasing:
    """The mesh phasing of `gs` (see :class:`MeshPhasing`). Jittable."""
    psi = gs.planet_angles
    return MeshPhasing(
        gamma_sp=jnp.mod(gs.z_sun * psi / (2 * jnp.pi), 1.0),
        gamma_rp=jnp.mod(-gs.z_ring * psi / (2 * jnp.pi), 1.0) + 0.0,  # no -0.0
        phase0_sp=jnp.zeros((), dtype=jnp.float64),
        phase0_rp=relative_mesh_phase(gs),
    )


def mesh_phases(
    gs: GearSet,
    theta_sun: ArrayLike,
    theta_carrier: ArrayLike,
    theta_ring: ArrayLike = 0.0,
) -> tuple[Float[Array, " N"], Float[Array, " N"]]:
    """Mesh phases of every planet's sun and ring mesh (cycles, not reduced mod 1).

        phase_sp_i = Zs (θ_s − θ_c − ψ_i)/2π + phase0_sp,
        phase_rp_i = Zr (θ_c − θ_r + ψ_i)/2π + phase0_rp.

    **Arguments:** absolute angles (rad) of sun, carrier and ring.

    **Returns:** ``(phase_sp, phase_rp)``, each of shape (N,).
    """
    ph = mesh_phasing(gs)
    psi = gs.planet_angles
    ts, tc, tr = _f64(theta_sun), _f64(theta_carrier), _f64(theta_ring)
    return (gs.z_sun * (ts - tc - psi) / (2 * jnp.pi) + ph.phase0_sp,
            gs.z_ring * (tc - tr + psi) / (2 * jnp.pi) + ph.phase0_rp)


# --- kinematics -------------------------------------------------------------------------------


def rigid_angles(gs: GearSet, theta_sun: ArrayLike) -> dict[str, Float[Array, "..."]]:
    """Rigid-body angles (rad) with the ring fixed, for a sun angle `theta_sun` (rad).

    ``θ_c = θ_s z_s/(z_s + z_r)``, ``θ_p = θ_c − (z_r/z_p) θ_c`` (absolute planet angle; the planet
    spins clockwise relative to the carrier), ``θ_r = 0``.

    **Returns:** dict with ``sun``, ``carrier``, ``planet``, ``ring``.
    """
    ts = _f64(theta_sun)
    tc = ts * gs.z_sun / (gs.z_sun + gs.z_ring)
    return {"sun": ts, "carrier": tc, "planet": tc - tc * gs.z_ring / gs.z_planet,
            "ring": jnp.zeros_like(ts)}


def characteristic_frequencies(
    gs: GearSet,
    f_sun: float,
    *,
    planet_fault: Literal["paper", "both_flanks"] = "paper",
) -> dict[str, float]:
    """Characteristic frequencies (Hz) of the gear set, ring fixed, sun input at `f_sun` (Hz).

    - ``f_sun``: absolute sun rotation (the paper's f_sr);
    - ``f_carrier = f_sun z_s/(z_s + z_r)``;
    - ``f_mesh = f_carrier z_r = (f_sun − f_carrier) z_s``;
    - ``f_sun_fault = f_mesh N / z_s`` (the paper's f_s);
    - ``f_planet_fault = f_mesh / z_p`` (``"paper"``, the paper's f_p) or ``2 f_mesh / z_p``
      (``"both_flanks"``: the faulty tooth strikes the sun and the ring once per relative turn);
    - ``f_ring_fault = f_mesh N / z_r``;
    - ``f_planet_pass = N f_carrier``;
    - ``f_planet = f_mesh / z_p``: planet spin relative to the carrier (magnitude).

    Computed by :class:`dtwin.model.kinematics.Kinematics` (the one place of these closed forms).
    Reference: Zhu, Li & Hu (2022), Eqs. (1)–(4); McFadden & Smith (1985); docs/references.md.
    """
    return Kinematics.from_gear_set(gs, f_sun, planet_fault=planet_fault).as_dict()


# --- masses and inertias ------------------------------------------------------------------------


def masses_and_inertias(gs: GearSet, density: float = STEEL_DENSITY) -> dict[str, Float[Array, ""]]:
    """Masses (kg) and polar moments of inertia (kg·m²) from the geometry.

    Assumptions (steel of `density` kg/m³, all bodies of width b = face width):

    - sun and planet: solid discs of the reference radius r (teeth and bore ignored; the tooth
      band between root and tip has about the mass of a ring of the reference radius);
      ``m = ρ π r² b``, ``J = m r²/2``;
    - ring: annulus from its reference radius to ``r_f,r + 3 m`` (a rim of three modules below
      the roots); ``m = ρ π (r_o² − r_i²) b``, ``J = m (r_o² + r_i²)/2``;
    - carrier: one solid plate of radius a + r_p (reaching the planets' outer edge) and
      thickness b/2 (pins and planets excluded; the dynamics adds ``N m_p a²``).

    **Returns:** dict ``m_sun, m_planet, m_ring, m_carrier, J_sun, J_planet, J_ring, J_carrier``.
    """
    r = reference_radii(gs)
    b = gs.face_width
    rho = float(density)
    out: dict[str, Float[Array, ""]] = {}
    for name, rr in (("sun", r[0]), ("planet", r[1])):
        m = rho * jnp.pi * rr**2 * b
        out[f"m_{name}"] = m
        out[f"J_{name}"] = 0.5 * m * rr**2
    ri = r[2]
    ro = root_radii(gs)[2] + RING_RIM * gs.module
    m_r = rho * jnp.pi * (ro**2 - ri**2) * b
    out["m_ring"] = m_r
    out["J_ring"] = 0.5 * m_r * (ro**2 + ri**2)
    rc = gs.centre_distance + r[1]
    m_c = rho * jnp.pi * rc**2 * (0.5 * b)
    out["m_carrier"] = m_c
    out["J_carrier"] = 0.5 * m_c * rc**2
    return out


def geometry_summary(gs: GearSet) -> dict[str, float | list[float]]:
    """A JSON-ready summary of the derived geometry (SI), for tables and manifests."""
    rb, ra, rf, r = base_radii(gs), tip_radii(gs), root_radii(gs), reference_radii(gs)
    a_sp, a_rp = operating_pressure_angles(gs)
    e_sp, e_rp = contact_ratios(gs)
    ph = mesh_phasing(gs)
    out: dict[str, float | list[float]] = {}
    for i, name in enumerate(("sun", "planet", "ring")):
        out[f"r_{name}"] = float(r[i])
        out[f"rb_{name}"] = float(rb[i])
        out[f"ra_{name}"] = float(ra[i])
        out[f"rf_{name}"] = float(rf[i])
    out.update(
        centre_distance=float(gs.centre_distance), x_sun=float(gs.x_sun),
        x_planet=float(gs.x_planet), x_ring=float(gs.x_ring),
        alpha_sp=float(a_sp), alpha_rp=float(a_rp), eps_sp=float(e_sp), eps_rp=float(e_rp),
        phase0_sp=float(ph.phase0_sp), phase0_rp=float(ph.phase0_rp),
        gamma_sp=[float(v) for v in ph.gamma_sp], gamma_rp=[float(v) for v in ph.gamma_rp],
        planet_angles=[float(v) for v in gs.planet_angles],
    )
    return out
