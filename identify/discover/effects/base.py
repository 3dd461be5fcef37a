"""Candidate effects: what a discrepancy search may add to a twin.

An effect is a final subclass of :class:`AbstractEffect`. It names

- the **part(s)** it adds (physics lives in ``dtwin/model/parts``): :meth:`AbstractEffect.parts`
  builds them from the effect's parameter vector ``theta`` (physical units);
- its **parameters** (:meth:`AbstractEffect.parameters`): names (declared by the effect and
  overlaid on :mod:`dtwin.model.registry` by a :class:`dtwin.model.registry.RegistryView`; the global
  registry is never changed), units, the *scale* of one fitting unit and whether the
  value is non-negative. ``theta = 0`` must give exactly the base model (nested models);
- its **signature** (:meth:`AbstractEffect.signature`): the spectral lines it adds to an ideal
  gearbox, as a function of the kinematics (:class:`dtwin.identify.lines.Kinematics`);
- its **main parameter** (:meth:`AbstractEffect.main`, a scalar of ``theta``: an amplitude) and
  the **typical range** of that amplitude on real machines (`typical_range`, with a note);
- its **group**: effects whose signatures coincide (look-alikes) share a group name; the search
  names the group and the member only where the data tell members apart.

Parameters enter the parts *linearly* wherever the physics allows (an eccentricity as its two
components rather than magnitude and phase), so that the first-order response about the base
model is exact in the parameters and the fit starts well (``identify/discover/``).

An effect may specialise itself to the machine and the record before the search
(:meth:`AbstractEffect.adapt`, given an :class:`EffectContext`): a planet-bearing defect reads
the bearing geometry from the spec, a housing resonance estimates its frequency from the
lines, a time-varying transfer path stands down when the base twin already has one. Returning
``None`` withdraws the candidate. The default keeps the effect as it is.

New effects plug in without touching the search: subclass, then pass an instance to
:func:`dtwin.identify.discover.discover` (``candidates=``) or call :func:`register_effect`. Only
`parameters`, `parts`, `signature` and `main` are required; `description`, `main_name`,
`main_unit`, `typical_range` and `typical_note` default to "not documented" placeholders (the
library's own effects document them all).
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Sequence
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from dtwin.model.kinematics import Kinematics, OrderBounds, combination_text
from dtwin.model.registry import ParameterInfo

from ...lines import comb_lines

__all__ = ["AbstractEffect", "EffectContext", "EffectParameter", "SignatureLine", "carrier_grid",
           "comb_grid", "register_effect", "registered_effects", "unregister_effect"]


@dataclasses.dataclass(frozen=True)
class EffectParameter:
    """One fitted coordinate of an effect.

    - `name`: registry name (e.g. ``sun_eccentricity_x``); `unit`: SI unit;
    - `scale`: physical value of one fitting unit (fits work on ``theta / scale`` ~ 1);
    - `nonnegative`: the value cannot be negative (fault severity, ripple amplitude bound);
    - `bounds`: hard physical bounds; `description`: one line.
    """

    name: str
    unit: str
    scale: float
    description: str
    bounds: tuple[float, float] = (-float("inf"), float("inf"))
    nonnegative: bool = False

    def info(self) -> ParameterInfo:
        """Its registry entry, for a :class:`dtwin.model.registry.RegistryView` overlay (the global
        registry is not changed: an effect's parameters belong to the search). It has no
        twin address: the effect builds its parts from the values (:meth:`AbstractEffect.parts`)."""
        lo, hi = self.bounds
        return ParameterInfo(
            self.name, self.unit, self.description, f"effects.{self.name}",
            (lo if lo > -float("inf") else -1e12, hi if hi < float("inf") else 1e12),
            "log" if self.nonnegative else "none", (lo, hi))


@dataclasses.dataclass(frozen=True)
class SignatureLine:
    """A line an effect adds: `frequency` (Hz) and its kinematic `label` ("fm + 2fc")."""

    frequency: float
    label: str


@dataclasses.dataclass(frozen=True)
class EffectContext:
    """What an effect may look at to specialise itself (:meth:`AbstractEffect.adapt`).

    `spec` (the gearbox spec), `base_twin`, `kin` (kinematics at the estimated speed); the
    whole-record Hann amplitude spectra `freqs` (Hz), `measured` and `model` (the base twin,
    gain-matched), the measured noise `floor`; `lines`: the residual lines of the base twin
    (:func:`dtwin.identify.lines.residual_lines`); `threshold_db`: line detection threshold;
    `tolerance_bins`: a line matches a frequency within this many bins of `freqs`;
    `modulation`: the family of a modulation at a located frequency in `lines`
    (:func:`dtwin.identify.lines.find_modulation`), None when there is none.
    """

    spec: object
    base_twin: object
    kin: Kinematics
    freqs: object = None
    measured: object = None
    model: object = None
    floor: object = None
    lines: tuple = ()
    threshold_db: float = 12.0
    tolerance_bins: float = 0.25
    modulation: object = None


class AbstractEffect(eqx.Module):
    """A candidate model augmentation (module docstring).

    Subclasses also provide `name` and `group` (str), as class variables or, when they depend
    on a field (a fault's location, a ripple's harmonic), as properties.
    """

    description: ClassVar[str] = "(not documented)"
    main_name: ClassVar[str] = "amplitude"
    main_unit: ClassVar[str] = ""
    typical_range: ClassVar[tuple[float, float]] = (float("nan"), float("nan"))
    typical_note: ClassVar[str] = "(typical range not documented)"
    #: True for effects that change lines the model already has (a resonance in the path)
    #: rather than adding new ones: the search then scores them on the model's own line bins
    #: within the signature too (by default those bins are left out of the statistic).
    modifies_model_lines: ClassVar[bool] = False

    def adapt(self, context: EffectContext) -> AbstractEffect | None:
        """This candidate specialised to the machine and record (module docstring); ``None``
        withdraws it. Default: unchanged."""
        del context
        return self

    @abc.abstractmethod
    def parameters(self, twin) -> tuple[EffectParameter, ...]:
        """The fitted coordinates (their number may depend on the twin, e.g. N planets)."""

    @abc.abstractmethod
    def parts(self, theta: Float[Array, " p"], twin, kin: Kinematics) -> tuple:
        """The parts for parameter values `theta` (physical units); theta = 0 → no effect."""

    @abc.abstractmethod
    def signature(self, kin: Kinematics, f_max: float) -> list[SignatureLine]:
        """Lines (Hz, up to `f_max`) the effect adds to the ideal gearbox."""

    @abc.abstractmethod
    def main(self, theta: Float[Array, " p"]) -> Float[Array, ""]:
        """The main amplitude (physical unit `main_unit`) of parameter values `theta`."""


_REGISTERED: dict[str, AbstractEffect] = {}


def register_effect(effect: AbstractEffect) -> AbstractEffect:
    """Make `effect` one of the default candidates of the search (by its `name`)."""
    _REGISTERED[effect.name] = effect
    return effect


def unregister_effect(name: str) -> None:
    _REGISTERED.pop(name, None)


def registered_effects() -> list[AbstractEffect]:
    """The default candidates, in registration order."""
    return list(_REGISTERED.values())


def mesh_orders_of_band(kin: Kinematics, f_max: float) -> range:
    """Mesh harmonics 0 … the last below `f_max` (and at least 0 … 4)."""
    return range(0, max(4, int(f_max // kin.f_mesh)) + 1)


def carrier_grid(kin: Kinematics, f_max: float, *, forbidden_only: bool = True,
                 mesh_orders: Sequence[int] | None = None, bounds: OrderBounds = OrderBounds()
                 ) -> list[SignatureLine]:
    """Lines ``m fm + n fc`` (|n| ≤ carrier bound, every mesh harmonic below `f_max` unless
    `mesh_orders` says otherwise) up to `f_max`; with `forbidden_only` only those the ideal
    gearbox's sideband rule cancels (docs/references.md §2)."""
    out = []
    for m in (mesh_orders_of_band(kin, f_max) if mesh_orders is None else mesh_orders):
        for n in range(-bounds.carrier, bounds.carrier + 1):
            f = m * kin.f_mesh + n * kin.f_carrier
            if not 0 < f < f_max or (m == 0 and n <= 0):
                continue
            if forbidden_only and kin.allowed_by_sideband_rule(m, n):
                continue
            out.append(SignatureLine(f, combination_text((("fm", m), ("fc", n)))))
    return out


def family_grid(kin: Kinematics, f_max: float, symbol: str, g: float, orders: Sequence[int],
                carrier: int = 2, mesh_orders: Sequence[int] | None = None
                ) -> list[SignatureLine]:
    """Lines ``m fm + j g + n fc`` for j in `orders`, |n| ≤ `carrier`, every mesh harmonic
    below `f_max` (unless `mesh_orders`), up to `f_max`."""
    out = []
    for m in (mesh_orders_of_band(kin, f_max) if mesh_orders is None else mesh_orders):
        for j in orders:
            for n in range(-carrier, carrier + 1):
                f = m * kin.f_mesh + j * g + n * kin.f_carrier
                if 0 < f < f_max:
                    out.append(SignatureLine(f, combination_text((("fm", m), (symbol, j),
                                                                  ("fc", n)))))
    return out


def rms(theta: Float[Array, " p"]) -> Float[Array, ""]:
    """Euclidean norm (used as the main amplitude of vector-valued effects)."""
    return jnp.sqrt(jnp.sum(theta**2))


def comb_grid(kin: Kinematics, f_max: float, symbol: str, g: float, carrier: int = 2,
              off_carrier_grid: bool = True) -> list[SignatureLine]:
    """The impulse comb of a repeating fault, ``k g + n fc`` for every k the band holds and
    |n| ≤ `carrier` (:func:`dtwin.identify.lines.comb_lines`): a short impulse at rate g has
    harmonics at every k g, low frequencies included, and the meshes carry them as sidebands
    ``m fm + j g + n fc`` (fm = Zs fs/N = Zp fp lies on the comb). With `off_carrier_grid`
    the teeth ``k g = m fm`` (j = 0: lines ``m fm + n fc`` that every planet-to-planet
    difference makes too) are left out, so the signature holds the lines that tell the fault
    apart from the ``carrier_sidebands`` group."""

    out = []
    for f, k, _, lab in comb_lines(kin, symbol, g, f_max, carrier):
        q = k * g / kin.f_mesh
        if off_carrier_grid and abs(q - round(q)) < 1e-9 * max(q, 1.0):
            continue
        out.append(SignatureLine(f, lab))
    return out
