"""Effects in the path to the sensor: a housing resonance, a time-varying (planet-pass) path."""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from dtwin.errors import SettingsError
from dtwin.model.kinematics import combination_text
from dtwin.model.parts.housing_resonance import HousingResonance
from dtwin.model.parts.transfer_path import PlanetPassTransferPath

from .base import AbstractEffect, EffectParameter, SignatureLine

#: Damping ratios tried when the resonance is located from the data.
ZETAS = (0.02, 0.035, 0.05, 0.07, 0.1)


def window_mean(p: float) -> float:
    """Mean over a turn of the planet window ``((1 + cos phi) / 2)^p``:
    ``Gamma(p + 1/2) / (sqrt(pi) Gamma(p + 1))`` (= C(2p, p) / 4^p for integer p)."""
    return math.exp(math.lgamma(p + 0.5) - math.lgamma(p + 1.0)) / math.sqrt(math.pi)


def _sensor_path(twin):
    paths = twin.find(PlanetPassTransferPath)
    return paths[0] if paths else None


def _grid_lines(kin, f_max, keep, carrier: int = 8):
    out = []
    for m in range(0, max(4, int(f_max // kin.f_mesh)) + 1):
        for n in range(-carrier, carrier + 1):
            f = m * kin.f_mesh + n * kin.f_carrier
            if 0 < f < f_max and keep(m, n, f):
                out.append(SignatureLine(f, combination_text((("fm", m), ("fc", n)))))
    return out


def _model_peaks(context):
    """Bins where the model has a line: local maxima of its spectrum over the detection
    threshold above the measured floor."""
    a, fl = np.asarray(context.model), np.asarray(context.floor)
    peak = np.r_[False, (a[1:-1] >= a[:-2]) & (a[1:-1] >= a[2:]), False]
    return peak & (a > fl * 10 ** (context.threshold_db / 20.0))


def common_line_excess(context):
    """Lines the base model has (over the threshold, local maxima) that the measurement also
    has: their frequencies (Hz) and the level excess measured − model (dB)."""
    f, y, a, fl = (np.asarray(v) for v in (context.freqs, context.measured, context.model,
                                            context.floor))
    k = np.flatnonzero(_model_peaks(context) & (y > fl * 10 ** (context.threshold_db / 20.0)))
    return f[k], 20.0 * np.log10(y[k] / a[k])


def model_line_frequencies(context):
    """Frequencies (Hz) of the lines the model carries (:func:`_model_peaks`)."""
    return np.asarray(context.freqs)[_model_peaks(context)]


def locate_resonance(freqs, excess_db, f_max):
    """Resonance (f_res, zeta, gain) whose path gain ``|1 + g (H − 1)|`` best explains the level
    excess of the common lines (least squares in dB, grid over f_res, zeta, g), or ``None``
    when no line stands ≥ 6 dB above the model."""
    if len(freqs) < 3 or np.max(excess_db) < 6.0:
        return None
    f_grid = np.geomspace(max(freqs.min() * 0.8, 50.0), min(freqs.max() * 1.25, f_max), 600)
    gains = np.linspace(0.05, 1.0, 20)
    best = (np.inf, None)
    for z in ZETAS:
        s = 1j * freqs[None, :] / f_grid[:, None]
        h = 1.0 / (s * s + 2 * z * s + 1.0)  # (R, L)
        pred = 20 * np.log10(np.abs(1.0 + gains[:, None, None] * (h[None] - 1.0)) + 1e-300)
        # the measured gain is fitted per record: compare excess up to a constant
        res = excess_db[None, None, :] - pred
        res = res - np.median(res, axis=-1, keepdims=True)
        cost = np.sum(np.minimum(res**2, 100.0), axis=-1)  # robust: other effects' lines
        i, j = np.unravel_index(np.argmin(cost), cost.shape)
        if cost[i, j] < best[0]:
            best = (cost[i, j], (float(f_grid[j]), z, float(gains[i])))
    return best[1]


class HousingResonanceEffect(AbstractEffect):
    """A housing mode in the transfer path, at `f_res` (Hz) with damping ratio `zeta`.

    Part: :class:`dtwin.model.parts.housing_resonance.HousingResonance` (gain linear, 0 = absent).
    `f_res` and `zeta` come from the data (:meth:`adapt`: the resonance curve that best explains
    the level excess of the lines the base model already has); the fit finds the gain. No new
    lines: the signature is the model's grid ``m fm + n fc`` (|n| ≤ 8) within
    ``f_res (1 ± 3 zeta)``, which the mode amplifies, and `model_lines`: the other lines the
    model it was located against carries in that band (a fault's comb once the fault is in the
    model), which it amplifies as well. Group ``housing_resonance``.
    """

    f_res: float | None = eqx.field(static=True, default=None)
    zeta: float = eqx.field(static=True, default=0.05)
    #: frequencies (Hz) of the lines the model carried within ``f_res (1 ± 3 zeta)`` when the
    #: resonance was located (:meth:`adapt`), besides the grid ``m fm + n fc``
    model_lines: tuple[float, ...] = eqx.field(static=True, default=())
    modifies_model_lines: ClassVar[bool] = True
    name: ClassVar[str] = "housing_resonance"
    group: ClassVar[str] = "housing_resonance"
    description: ClassVar[str] = "a housing resonance in the transfer path"
    main_name: ClassVar[str] = "share of the force path through the mode"
    main_unit: ClassVar[str] = "1"
    typical_range: ClassVar[tuple[float, float]] = (0.1, 1.0)
    typical_note: ClassVar[str] = (
        "gearbox housing modes 1–5 kHz with damping ratios 0.02–0.1 (amplification 5–25 at "
        "resonance) are the rule on industrial casings; the share of the path through one mode "
        "is 0.1–1")

    @property
    def summary(self) -> str:
        """What the step adds, in words ("housing resonance at 1541.9 Hz, damping ratio 0.1")."""
        if self.f_res is None:
            return "housing resonance"
        return f"housing resonance at {self.f_res:.1f} Hz, damping ratio {self.zeta:g}"

    def adapt(self, context):
        if self.f_res is not None:
            return self
        if context.freqs is None:
            return None
        f, ex = common_line_excess(context)
        found = locate_resonance(f, ex, float(np.asarray(context.freqs)[-1]))
        if found is None:
            return None
        located = HousingResonanceEffect(f_res=found[0], zeta=found[1])
        freqs = np.asarray(context.freqs)
        lo, hi = located.band()
        grid = np.array([s.frequency for s in located.signature(context.kin, float(freqs[-1]))])
        tol = context.tolerance_bins * float(freqs[1] - freqs[0])
        own = tuple(float(x) for x in model_line_frequencies(context)
                    if lo <= x <= hi and (grid.size == 0 or np.min(np.abs(grid - x)) > tol))
        return HousingResonanceEffect(f_res=found[0], zeta=found[1], model_lines=own)

    def band(self) -> tuple[float, float]:
        """The band the mode amplifies, ``f_res (1 ± 3 zeta)`` (Hz)."""
        return self.f_res * (1 - 3 * self.zeta), self.f_res * (1 + 3 * self.zeta)

    def parameters(self, twin):
        return (EffectParameter("housing_resonance_gain", "1", 0.1,
                                "share of the force path through the housing mode"),)

    def parts(self, theta, twin, kin):
        if self.f_res is None:
            raise SettingsError("HousingResonanceEffect needs f_res (adapt() on the data)")
        p = _sensor_path(twin)
        kw = {} if p is None else dict(sensor_angle=p.sensor_angle,
                                       window_exponent=p.window_exponent)
        return (HousingResonance(theta[0], jnp.asarray(self.f_res), jnp.asarray(self.zeta),
                                 **kw),)

    def signature(self, kin, f_max):
        if self.f_res is None:
            return []
        lo, hi = self.band()
        return (_grid_lines(kin, f_max, lambda m, n, f: lo <= f <= hi)
                + [SignatureLine(f, f"{f:.2f} Hz, a line of the model the mode amplifies")
                   for f in self.model_lines if f < f_max])

    def main(self, theta):
        return jnp.abs(theta[0])


class TimeVaryingPathEffect(AbstractEffect):
    """The planet-pass window of the transfer path, for a base twin whose path is fixed.

    Parts: two :class:`dtwin.model.parts.transfer_path.PlanetPassTransferPath` force paths (no ring
    term), ``+a / c_p`` with the window ``((1 + cos phi)/2)^p`` and ``−a`` without (exponent
    0), ``c_p`` the window's mean (:func:`window_mean`): the fixed force path ``sum F_i`` becomes
    ``sum (1 + a (w_i / c_p − 1)) F_i`` — a modulation of depth a with unit mean, so the lines
    the path already carries keep their level and only the sidebands grow with a (an effect
    that also rescaled the main lines would trade against the fitted gain: magnitude-only fits
    then have a mirror solution). a = 1: the windowed path (up to the gain); a = 0: nothing;
    linear in a. Only
    offered when the base twin's path has no window (:meth:`adapt`). Each planet's mesh force
    is modulated at carrier orders as it passes the sensor; summed over equally spaced planets
    the modulation leaves the lines the sideband rule allows, ``m fm + n fc``, ``(m Zr + n) mod N
    = 0``, n ≠ 0 — uniform modulation at carrier orders, group ``carrier_sidebands``.
    """

    window_exponent: float = eqx.field(static=True, default=4.0)
    name: ClassVar[str] = "time_varying_path"
    group: ClassVar[str] = "carrier_sidebands"
    description: ClassVar[str] = "time-varying (planet-pass) transfer path"
    main_name: ClassVar[str] = "weight of the windowed force path"
    main_unit: ClassVar[str] = "1"
    typical_range: ClassVar[tuple[float, float]] = (0.2, 1.0)
    typical_note: ClassVar[str] = (
        "McFadden & Smith (1985), Inalpolat & Kahraman (2009): on a housing-mounted sensor the "
        "planet passing dominates the mesh-frequency sidebands; the windowed share of the path "
        "is 0.2–1")

    def adapt(self, context):
        p = _sensor_path(context.base_twin)
        if p is not None and float(p.window_exponent) > 0:
            return None
        return self

    def parameters(self, twin):
        return (EffectParameter("time_varying_path_weight", "1", 0.1,
                                "weight of the windowed (planet-pass) force path"),)

    def parts(self, theta, twin, kin):
        p = _sensor_path(twin)
        ang = p.sensor_angle if p is not None else jnp.asarray(jnp.pi / 2)
        zero = jnp.zeros(())
        c = window_mean(self.window_exponent)
        return (PlanetPassTransferPath(sensor_angle=ang, window_exponent=jnp.asarray(
                    self.window_exponent), ring_weight=zero, force_weight=theta[0] / c),
                PlanetPassTransferPath(sensor_angle=ang, window_exponent=zero, ring_weight=zero,
                                       force_weight=-theta[0]))

    def signature(self, kin, f_max):
        return _grid_lines(kin, f_max, lambda m, n, f: n != 0 and
                           kin.allowed_by_sideband_rule(m, n))

    def main(self, theta):
        return jnp.abs(theta[0])
