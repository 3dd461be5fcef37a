"""The lumped parameters a spec implies (:func:`lumped_from_spec`): geometry from the gear set,
masses and inertias from the geometry, mesh stiffness from ISO 6336-1, unless the spec's
``[mesh]`` and ``[lumped]`` sections give them."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..errors import SpecError
from ..model.gears import (
    base_radii,
    contact_ratios,
    masses_and_inertias,
    operating_pressure_angles,
    reference_radii,
    relative_mesh_phase,
)
from ..model.lumped import make_lumped
from ..model.stiffness import mesh_stiffness_mean

if TYPE_CHECKING:
    from . import Spec


def lumped_from_spec(spec: Spec, *, model: str | None = None):
    """The :class:`~dtwin.model.lumped.LumpedParameters` a spec implies.

    - Geometry (base radii, centre distance, operating pressure angles, contact ratios, planet
      angles ψ_i + ``imperfections.planet_position_errors``, mesh phases) from
      :class:`~dtwin.model.gears.GearSet`.
    - Masses and inertias from :func:`dtwin.model.gears.masses_and_inertias` (``material.density``)
      unless ``[lumped]`` gives ``m_*``, ``J_*`` or ``Ir2_*`` (``J = Ir2 r²`` with r the base
      radius of sun, ring, planet and the centre distance for the carrier).
    - Mean mesh stiffnesses from ISO 6336-1 (:func:`dtwin.model.stiffness.mesh_stiffness_mean`) unless
      ``mesh.k_sun_planet`` / ``mesh.k_ring_planet`` are given. The load enters through the
      nominal tangential force per planet mesh at the sun's reference circle,
      ``F_t = T_sun / (N r_s)`` with ``T_sun = T_load z_s/(z_s + z_r)`` (ring fixed, no losses;
      the ring mesh carries the same force). With ``load_torque = 0`` the load factor is left out
      (ISO's line load of at least 100 N/mm). The ring's shift is passed to ISO with ISO 21771's
      sign for internal gears (positive towards the tips), i.e. ``−x_ring``.
    - Supports and damping from ``[supports]`` and ``[damping]``; ``lumped.k_u_torsion_*``
      (Lin & Parker's N/m on u = r θ) become ``k_torsion = k_u r²`` and win over ``[supports]``.

    **Arguments:** `spec`; `model`: ``translational`` or ``torsional`` (default ``[model].kind``;
    both use the same parameters, the torsional reduction ignores the translational supports).

    **Returns:** ``LumpedParameters`` (float64).
    """
    import jax.numpy as jnp
    import numpy as np

    kind = model if model is not None else spec["model"]["kind"]
    if kind not in ("translational", "torsional"):
        raise SpecError([("model.kind", f"must be translational or torsional, got {kind!r}")])
    gs = spec.gear_set()
    rb = base_radii(gs)
    a = gs.centre_distance
    a_sp, a_rp = operating_pressure_angles(gs)
    eps_sp, eps_rp = contact_ratios(gs)
    psi = np.asarray(gs.planet_angles)
    err = spec["imperfections"]["planet_position_errors"]
    if err is not None:
        psi = psi + np.asarray(err, dtype=np.float64)

    lum = spec["lumped"]
    geo = masses_and_inertias(gs, density=spec["material"]["density"])
    radius = {"sun": rb[0], "planet": rb[1], "ring": rb[2], "carrier": a}
    vals: dict[str, Any] = {}
    for b in ("sun", "ring", "carrier", "planet"):
        vals[f"m_{b}"] = lum[f"m_{b}"] if lum[f"m_{b}"] is not None else geo[f"m_{b}"]
        if lum[f"J_{b}"] is not None:
            vals[f"J_{b}"] = lum[f"J_{b}"]
        elif lum[f"Ir2_{b}"] is not None:
            vals[f"J_{b}"] = lum[f"Ir2_{b}"] * radius[b] ** 2
        else:
            vals[f"J_{b}"] = geo[f"J_{b}"]

    sup = spec["supports"]
    for b in ("sun", "ring", "carrier"):
        ku = lum[f"k_u_torsion_{b}"]
        vals[f"k_torsion_{b}"] = sup[f"k_torsion_{b}"] if ku is None else ku * radius[b] ** 2
    for b in ("sun", "ring", "carrier", "planet"):
        vals[f"k_bearing_{b}"] = sup[f"k_bearing_{b}"]

    mesh = spec["mesh"]
    k_sp, k_rp = mesh["k_sun_planet"], mesh["k_ring_planet"]
    if k_sp is None or k_rp is None:
        t_load = spec["operating"]["load_torque"]
        ft = None
        if t_load > 0:
            t_sun = t_load * gs.z_sun / (gs.z_sun + gs.z_ring)
            ft = t_sun / (gs.n_planets * reference_radii(gs)[0])
        common = dict(pressure_angle=gs.pressure_angle, tangential_force=ft,
                      K_A=mesh["application_factor"])
        if k_sp is None:
            k_sp = mesh_stiffness_mean(gs.z_sun, gs.z_planet, gs.face_width, eps_sp,
                                       x1=gs.x_sun, x2=gs.x_planet, internal=False, **common)
        if k_rp is None:
            # ISO 6336 / ISO 21771 count an internal gear's shift positive towards its tips
            # (towards the axis): the opposite of dtwin's x_ring (see dtwin.model.gears).
            k_rp = mesh_stiffness_mean(gs.z_planet, gs.z_ring, gs.face_width, eps_rp,
                                       x1=gs.x_planet, x2=-gs.x_ring, internal=True, **common)

    damp = spec["damping"]
    return make_lumped(
        z_sun=gs.z_sun, z_planet=gs.z_planet, z_ring=gs.z_ring, n_planets=gs.n_planets,
        planet_angles=jnp.asarray(psi, dtype=jnp.float64),
        rb_sun=rb[0], rb_planet=rb[1], rb_ring=rb[2], centre_distance=a,
        alpha_sp=a_sp, alpha_rp=a_rp, eps_sp=eps_sp, eps_rp=eps_rp,
        phase0_sp=0.0, phase0_rp=relative_mesh_phase(gs),
        k_sun_planet=k_sp, k_ring_planet=k_rp,
        zeta_sun_planet=damp["zeta_sun_planet"], zeta_ring_planet=damp["zeta_ring_planet"],
        zeta_support=damp["zeta_support"],
        **vals,
    )
