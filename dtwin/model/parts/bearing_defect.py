"""A local defect in a planet bearing: impacts at the bearing's characteristic frequencies.

A planet bearing's inner race sits on the carrier pin; its outer race is the planet bore and
turns with the planet at ``f_r = fm / Zp`` relative to the pin (the carrier frame). With `n`
rolling elements of diameter `d` on pitch diameter `D` and contact angle `alpha`, the defect
frequencies in the carrier frame are (Harris, *Rolling Bearing Analysis*; Randall & Antoni
2011 for the planet-bearing case)::

    cage relative to the planet  FTF  = f_r / 2 (1 − d/D cos alpha)   (the usual FTF)
    cage relative to the pin     f_cage = f_r / 2 (1 + d/D cos alpha)
    outer race (planet bore)     BPFO = n f_r / 2 (1 − d/D cos alpha)
    inner race (pin)             BPFI = n f_r / 2 (1 + d/D cos alpha)
    rolling element (spin)       BSF  = D / (2 d) f_r (1 − (d/D cos alpha)^2)

(:func:`bearing_frequencies`). The bearing load of a planet is carried in one direction of the
carrier frame (the sum of its two mesh forces), so a defect on the pin (inner race) is always in
the load zone, a defect on the planet bore passes through it once per planet turn (modulation
at ``f_r``) and a rolling-element defect once per turn of the cage relative to the pin
(``f_cage``; the element strikes both races, so its impacts repeat at ``2 BSF``).

**Model.** When a rolling element meets the defect the planet drops onto it in the load
direction, which relieves both of the planet's meshes: the part subtracts ``a p(t)`` (m) from
the sun–planet and ring–planet deflections of the defective planet, with a smooth unit pulse
train ``p = ((1 + cos phi_d) / 2)^k − c_k`` (``c_k = C(2k, k) / 4^k`` its mean, removed so
that the defect does not shift the static mesh deflection), ``phi_d`` the defect angle (defect order × the planet's
rotation relative to the carrier, from the shaft angles, so speed fluctuation is followed),
times the load-zone window ``(1 + cos phi_m) / 2`` for the rotating defects. `amplitude` = 0
gives exactly no excitation; the excitation is linear in it. The sensor sees the excitation
through the meshes and the planet-pass transfer path: lines ``j f_d + n fc`` and
``m fm ± j f_d + n fc``.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .base import AbstractPart, Modulation

__all__ = ["BEARING_DEFECTS", "PlanetBearingDefect", "bearing_frequencies"]

#: Defect locations: race → (defect order name, modulation order name or None).
BEARING_DEFECTS = {"outer": ("bpfo", "f_r"), "inner": ("bpfi", None),
                   "ball": ("bsf2", "cage")}


def bearing_frequencies(n_rolling_elements: int, ball_diameter: float, pitch_diameter: float,
                        contact_angle: float = 0.0, f_rel: float = 1.0) -> dict[str, float]:
    """Characteristic frequencies of a bearing whose outer race turns at `f_rel` (Hz) relative
    to its inner race (module docstring): ``ftf``, ``cage`` (cage relative to the inner race),
    ``bpfo``, ``bpfi``, ``bsf``, ``bsf2`` (= 2 BSF, the impact rate of an element defect) and
    ``f_r`` (= `f_rel`), in Hz.

    **Arguments:** number of rolling elements; element and pitch diameters (m); contact angle
    (rad); relative speed of the races `f_rel` (Hz; 1 gives orders of the relative rotation).
    """
    r = ball_diameter / pitch_diameter * math.cos(contact_angle)
    n = n_rolling_elements
    bsf = pitch_diameter / (2.0 * ball_diameter) * f_rel * (1.0 - r * r)
    return dict(ftf=0.5 * f_rel * (1.0 - r), cage=0.5 * f_rel * (1.0 + r), bpfo=0.5 * n * f_rel * (1.0 - r),
                bpfi=0.5 * n * f_rel * (1.0 + r), bsf=bsf, bsf2=2.0 * bsf, f_r=f_rel)


class PlanetBearingDefect(AbstractPart):
    """A local defect in one planet's bearing (module docstring).

    - `amplitude` (m): depth of the planet's drop at a defect impact (≥ 0 physically; the
      model is linear in it);
    - `defect_order`: defect frequency over the planet's rotation relative to the carrier
      (e.g. BPFO / f_r); `modulation_order`: load-zone modulation over the same (1 for an outer
      race, f_cage / f_r for a rolling element, 0 for none);
    - `planet` (static): which planet; `sharpness` (static): pulse exponent `k` (harmonics up
      to about `k` of the defect frequency carry the energy).
    """

    amplitude: Float[Array, ""]
    defect_order: float = eqx.field(static=True, default=1.0)
    modulation_order: float = eqx.field(static=True, default=0.0)
    planet: int = eqx.field(static=True, default=0)
    sharpness: int = eqx.field(static=True, default=8)

    def __check_init__(self):
        if not self.defect_order > 0 or self.modulation_order < 0 or self.sharpness < 1:
            raise ValueError("PlanetBearingDefect: defect_order must be > 0, modulation_order "
                             f">= 0 and sharpness >= 1, got {self.defect_order}, "
                             f"{self.modulation_order}, {self.sharpness}")

    def modulation(self, twin, t, q, qdot):
        n = twin.n_planets
        if not 0 <= self.planet < n:
            raise ValueError(f"PlanetBearingDefect.planet must be in 0 … {n - 1}, got "
                             f"{self.planet}")
        # planet rotation relative to the carrier (increasing, rad)
        spin = -(q.theta_p[self.planet] - q.theta_c)
        k = self.sharpness
        pulse = (0.5 * (1.0 + jnp.cos(self.defect_order * spin))) ** k - math.comb(2 * k, k) / 4**k
        if self.modulation_order > 0:
            pulse = pulse * 0.5 * (1.0 + jnp.cos(self.modulation_order * spin))
        e = jnp.zeros(n).at[self.planet].set(self.amplitude * pulse)
        z = jnp.zeros(n)
        return Modulation(z, z, z, z, e, e)
