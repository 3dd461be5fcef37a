"""Whether a fitted mesh stiffness is one the spec's gear pair can have.

A record of a few kHz sees the mesh stiffness through the mesh modes' tails and through the
products it forms with the excitation, and a twin that lacks an effect can bend the stiffness
to stand in for it: the fit then finds a value with a narrow interval that only says how well
the stand-in is pinned. The interval cannot say that the value is physically out of reach;
the gear pair's geometry can. ISO 6336-1:2006, clause 9, method B, gives the mean mesh
stiffness of a steel spur pair from its teeth, profile shifts, face width and load
(:func:`dtwin.model.stiffness.mesh_stiffness_mean`); its corrections for rim, basic rack and load
each move the single-pair stiffness ``c'`` by well under a factor of two. For another material
pairing ``c'`` scales with the Young's modulus (ISO 6336-1, clause 9: ``c'`` of steel times
``E / E_steel``, ``E_steel`` = 206 GPa); the check takes the spec's ``[material]
youngs_modulus`` so.

**The check** (:func:`implausible_stiffness`). A fitted ``k_sun_planet`` or ``k_ring_planet``
more than :data:`ISO_FACTOR` times above or below the ISO 6336-1 value of the spec's own
geometry and material (computed as :func:`dtwin.spec.lumped_from_spec` computes it when the
spec gives no stiffness) is flagged NOT DETERMINED, with the ratio in the reason and the value
kept as indicative; so is every parameter fitted beside it, whose value and interval hold only
at that stiffness. A twin passed without its spec is not checked.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from dtwin.spec import load_spec, lumped_from_spec, spec_to_dict

ISO_FACTOR = 3.0
"""How far (a factor, either way) a fitted mean mesh stiffness may lie from the ISO 6336-1
value of the spec's gear pair before it is flagged."""

E_STEEL = 2.06e11
"""Young's modulus of steel (Pa), the material ISO 6336-1's ``c'`` is given for."""

MESHES = ("k_sun_planet", "k_ring_planet")
"""The registry names of the mean mesh stiffnesses the check covers (N/m)."""


def iso_mesh_stiffness(spec) -> dict[str, float]:
    """ISO 6336-1 mean mesh stiffness (N/m) of each mesh of `spec` (a
    :class:`dtwin.spec.Spec`), from its geometry and load, scaled by its Young's modulus over
    steel's, whatever stiffness the spec itself gives."""
    data = spec_to_dict(spec)
    data.pop("source", None)
    data["mesh"] = {k: v for k, v in data.get("mesh", {}).items() if k not in MESHES}
    lp = lumped_from_spec(load_spec(data))
    material = float(spec["material"]["youngs_modulus"]) / E_STEEL
    return {name: float(getattr(lp, name)) * material for name in MESHES}


def implausible_stiffness(values: dict[str, Any], spec) -> dict[str, str]:
    """The fitted mesh stiffnesses among `values` (registry name → SI value) that lie more
    than :data:`ISO_FACTOR` from the ISO 6336-1 value of `spec`'s gear pair, each with the
    reason (module docstring). Empty when there is nothing to flag or no spec."""
    names = [n for n in MESHES if n in values]
    if spec is None or not names:
        return {}
    iso = iso_mesh_stiffness(spec)
    out = {}
    for n in names:
        ratio = float(values[n]) / iso[n]
        if not (1.0 / ISO_FACTOR <= ratio <= ISO_FACTOR):
            out[n] = (f"implausible for this gear pair: {ratio:.3g}× the ISO 6336-1 mean mesh "
                      f"stiffness of its geometry ({iso[n]:.4g} N/m), beyond the factor "
                      f"{ISO_FACTOR:g} a steel mesh stays within; the fit bends the stiffness "
                      "to stand in for what the twin lacks (value indicative)")
    return out


def flag_implausible(unc, values: dict[str, Any], spec):
    """`unc` (:class:`dtwin.identify.uncertainty.Uncertainty`) with the implausible mesh
    stiffnesses of `values` (the fit's free parameters) added to ``not_determined``, and every
    other free parameter flagged as fitted beside them: its value and interval hold only at a
    stiffness the gear pair cannot have. A flag already there is kept."""
    flags = implausible_stiffness(values, spec)
    if unc is None or not flags:
        return unc
    merged = dict(unc.not_determined)
    for n, why in flags.items():
        merged.setdefault(n, why)
    bent = ", ".join(flags)
    for n in values:
        merged.setdefault(n, f"fitted beside an implausible mesh stiffness ({bent}): its value "
                             "and interval hold only at that stiffness (value indicative)")
    return dataclasses.replace(unc, not_determined=merged)
