"""Time-synchronous averaging (TSA) and McFadden's separation of the planets' vibration.

**TSA** (:func:`time_synchronous_average`): the signal is resampled on a uniform grid of the
reference shaft's angle (:func:`dtwin.signal.order.resample_to_angle`), cut into whole revolutions
starting at angle 0 (mod 2 pi), and averaged. Components locked to the shaft (its orders) stay;
asynchronous ones are attenuated by the comb filter (McFadden 1987)

    |H(f)| = |sin(pi n r) / (n sin(pi r))|,  r = f / f_shaft   (n = number of averages)

which is 1 at integer orders and falls to about ``1 / (n pi |r - k|)`` between them; white noise
loses ``sqrt(n)`` in RMS. The shaft is chosen through the angle passed:

- the carrier: its angle from a tachometer on the output (:func:`dtwin.signal.order.tacho_angle`), or
  ``theta_s / (1 + Zr/Zs)`` from a sun tacho (ring fixed);
- the sun *relative to the carrier* (:func:`sun_relative_angle`: ``theta_s - theta_c =
  theta_c Zr / Zs``): a local sun fault meets the planets at fixed relative angles, so this
  average keeps its signature (N impacts per relative revolution).

**Planet separation** (:func:`planet_separation`, McFadden 1991, JSV 144:163; window functions
McFadden 1994, JSV 170:673; as applied by Samuel & Pines 2005, JSV 282:475). With the
conventions of ``docs/conventions.md`` planet i sits at carrier-frame angle ``psi_i`` and is
closest to the sensor (housing angle `sensor_angle`, default pi/2) when
``theta_c + psi_i - sensor_angle = 0 (mod 2 pi)``. Its ring mesh has passed
``q_i = Zr (theta_c + psi_i) / 2 pi`` tooth pitches, so the planet tooth in the ring mesh is
``q_i mod Zp``. Around each passage the signal, weighted by a window of `window_teeth` mesh
periods centred on the passage, is accumulated at the planet-tooth position ``q_i mod Zp``; the
weighted mean over all passages is planet i's average over one planet revolution relative to the
carrier (``Zp`` mesh periods). From one passage to the next the tooth at the centre advances by
``Zr mod Zp``, so the centres visit the positions spaced ``g = gcd(Zr, Zp)`` teeth apart; the
default Hann window of full width ``2 g`` teeth sums to a constant over those centres (a partition
of unity, McFadden 1994), a rectangular window of width ``g`` tiles them (McFadden 1991). At least
``Zp / g`` carrier revolutions are needed to see every tooth.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from ..errors import RecordError
from .order import resample_to_angle
from .spectrum import as_signal

__all__ = [
    "PlanetAverages",
    "TSA",
    "planet_separation",
    "sun_relative_angle",
    "time_synchronous_average",
]


@dataclasses.dataclass(frozen=True)
class TSA:
    """A time-synchronous average over one revolution of the reference shaft.

    - `angle`: grid angles (rad), ``2 pi k / samples_per_rev``, k = 0 … samples_per_rev - 1.
    - `average`: the average (unit of the signal).
    - `n_averages`: number of whole revolutions averaged.
    - `revolutions`: every revolution, shape ``(n_averages, samples_per_rev)`` (for NA4
      histories or the scatter of the average).
    """

    angle: np.ndarray
    average: np.ndarray
    n_averages: int
    revolutions: np.ndarray

    @property
    def samples_per_rev(self) -> int:
        return int(self.angle.size)


def sun_relative_angle(carrier_angle: np.ndarray, z_sun: int, z_ring: int) -> np.ndarray:
    """Sun angle relative to the carrier (rad), ring fixed: ``theta_s - theta_c = theta_c Zr/Zs``.

    From the rigid kinematics ``theta_s = theta_c (1 + Zr / Zs)`` (conventions.md).
    """
    if z_sun <= 0 or z_ring <= 0:
        raise RecordError(f"tooth counts must be positive, got Zs={z_sun}, Zr={z_ring}")
    return np.asarray(carrier_angle, dtype=np.float64) * (z_ring / z_sun)


def time_synchronous_average(
    x,
    angle: np.ndarray,
    samples_per_rev: int,
    *,
    sample_rate: float | None = None,
    channel: str | int = 0,
    anti_alias: bool = True,
) -> TSA:
    """Average the signal over whole revolutions of the shaft whose `angle` is given.

    **Arguments:**

    - `x`: a signal (1-D numpy array, then `sample_rate` in Hz is required) or a
      :class:`dtwin.io.Record` (its `channel` and rate are used).
    - `angle`: the reference-shaft angle (rad) at every sample, strictly increasing.
    - `samples_per_rev`: resolution of the average (points per revolution; orders up to half of
      it are kept).
    - `anti_alias`: as :func:`dtwin.signal.order.resample_to_angle`.

    **Returns:** a :class:`TSA`. Raises `RecordError` with fewer than two whole revolutions.
    """
    sig, fs = as_signal(x, sample_rate, channel)
    spr = int(samples_per_rev)
    grid, xa = resample_to_angle(sig, fs, angle, spr, anti_alias=anti_alias)
    k0 = int(round(grid[0] / (2 * np.pi / spr)))
    start = (-k0) % spr  # first grid point at a multiple of 2 pi
    n_rev = (xa.size - start) // spr
    if n_rev < 2:
        raise RecordError(
            f"the record covers {grid.size / spr:.2f} revolutions of the shaft; a TSA needs at "
            "least two whole ones (use a longer record)"
        )
    revs = xa[start : start + n_rev * spr].reshape(n_rev, spr)
    return TSA(2 * np.pi * np.arange(spr) / spr, revs.mean(axis=0), n_rev, revs)


@dataclasses.dataclass(frozen=True)
class PlanetAverages:
    """McFadden's separated planet averages.

    - `tooth`: planet-tooth positions (teeth, 0 … Zp), ``samples_per_tooth`` per tooth.
    - `averages`: shape ``(N, Zp * samples_per_tooth)``, planet i's windowed average (unit of
      the signal); NaN where no passage covered a position.
    - `weights`: total window weight per position and planet (coverage).
    - `n_passes`: passages of each planet under the sensor used.
    - `window`, `window_teeth`: the window used (name, full width in mesh periods).
    """

    tooth: np.ndarray
    averages: np.ndarray
    weights: np.ndarray
    n_passes: np.ndarray
    window: str
    window_teeth: float

    @property
    def complete(self) -> bool:
        """True when every planet-tooth position of every planet was covered."""
        return bool(np.all(self.weights > 0))


def _window_weight(u: np.ndarray, name: str) -> np.ndarray:
    """Window over ``u`` in units of its full width, centred at 0 (zero for |u| > 1/2)."""
    inside = np.abs(u) <= 0.5
    if name == "hann":
        return np.where(inside, np.cos(np.pi * u) ** 2, 0.0)
    if name == "rect":
        return np.where(np.abs(u) < 0.5, 1.0, np.where(inside, 0.5, 0.0))
    raise RecordError(f"unknown planet-separation window {name!r}; choose 'hann' or 'rect'")


def _passage_window(grid, psi_i, sensor_angle, z_ring, width, window):
    """Window weight of one planet's passage under the sensor at carrier angles `grid`, and the
    number of passages it covers (shared by planet and sun separation)."""
    phi = np.angle(np.exp(1j * (grid + psi_i - sensor_angle)))  # angle to sensor, (-pi, pi]
    w = _window_weight(phi * z_ring / (2 * np.pi) / width, window)
    rev = np.round((grid + psi_i - sensor_angle) / (2 * np.pi))
    return w, int(np.unique(rev[w > 0]).size)


def planet_separation(
    x,
    carrier_angle: np.ndarray,
    z_ring: int,
    z_planet: int,
    n_planets: int,
    *,
    planet_angles: Sequence[float] | None = None,
    sensor_angle: float = np.pi / 2,
    samples_per_tooth: int = 16,
    window: str = "hann",
    window_teeth: float | None = None,
    sample_rate: float | None = None,
    channel: str | int = 0,
) -> PlanetAverages:
    """Separate each planet's ring-mesh vibration by windowed averaging (module docstring).

    **Arguments:**

    - `x`: a signal (with `sample_rate`, Hz) or a :class:`dtwin.io.Record` (`channel`).
    - `carrier_angle`: absolute carrier angle (rad) at every sample (0 at t = 0 in the twin).
    - `z_ring`, `z_planet`, `n_planets`: tooth counts and number of planets.
    - `planet_angles`: carrier-frame planet angles ``psi_i`` (rad); default ``2 pi i / N``.
    - `sensor_angle`: housing angle of the sensor (rad, CCW from +x; default pi/2, on top).
    - `samples_per_tooth`: resolution of the averages (points per mesh period).
    - `window`: ``"hann"`` (McFadden 1994) or ``"rect"`` (McFadden 1991).
    - `window_teeth`: full window width in mesh periods; default ``2 g`` (hann) or ``g`` (rect),
      ``g = gcd(Zr, Zp)``.

    **Returns:** :class:`PlanetAverages`.
    """
    sig, fs = as_signal(x, sample_rate, channel)
    zr, zp, n = int(z_ring), int(z_planet), int(n_planets)
    if min(zr, zp, n) < 1:
        raise RecordError(f"Zr, Zp and N must be positive integers, got {z_ring}, {z_planet}, {n_planets}")
    psi = (2 * np.pi * np.arange(n) / n if planet_angles is None
           else np.asarray(planet_angles, dtype=np.float64))
    if psi.shape != (n,):
        raise RecordError(f"planet_angles must hold {n} angles (rad), got {len(psi)}")
    g = math.gcd(zr, zp)
    width = float(window_teeth) if window_teeth is not None else (2.0 * g if window == "hann" else float(g))
    if width <= 0:
        raise RecordError(f"window_teeth must be positive, got {window_teeth}")
    spt = int(samples_per_tooth)
    spr = zr * spt
    grid, xa = resample_to_angle(sig, fs, carrier_angle, spr)
    n_bins = zp * spt
    averages = np.full((n, n_bins), np.nan)
    weights = np.zeros((n, n_bins))
    passes = np.zeros(n, dtype=np.int64)
    for i in range(n):
        w, passes[i] = _passage_window(grid, psi[i], sensor_angle, zr, width, window)
        q = zr * (grid + psi[i]) / (2 * np.pi)  # ring-mesh cycles of planet i
        idx = np.mod(np.round(q * spt).astype(np.int64), n_bins)
        num = np.bincount(idx, weights=w * xa, minlength=n_bins)
        den = np.bincount(idx, weights=w, minlength=n_bins)
        weights[i] = den
        averages[i] = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
    return PlanetAverages(np.arange(n_bins) / spt, averages, weights, passes, window, width)


@dataclasses.dataclass(frozen=True)
class SunAverage:
    """The sun gear's windowed average (McFadden 1994, sun-gear form of planet separation).

    - `tooth`: sun-tooth positions (teeth, 0 … Zs), ``samples_per_tooth`` per tooth.
    - `average`: the windowed average over every planet's passages, shape ``(Zs * spt,)``.
    - `weights`: total window weight per position (coverage); `n_passes`: planet passages used.
    """

    tooth: np.ndarray
    average: np.ndarray
    weights: np.ndarray
    n_passes: int


def sun_separation(
    x,
    carrier_angle: np.ndarray,
    z_sun: int,
    z_ring: int,
    n_planets: int,
    *,
    planet_angles: Sequence[float] | None = None,
    sensor_angle: float = np.pi / 2,
    samples_per_tooth: int = 16,
    window: str = "hann",
    window_teeth: float | None = None,
    sample_rate: float | None = None,
    channel: str | int = 0,
) -> SunAverage:
    """Average the vibration of the sun's teeth as they mesh with the planet under the sensor.

    While planet i passes the sensor (window of its angle to the sensor, as in
    :func:`planet_separation`), the sun tooth in mesh with it is
    ``(phase_sp_i mod Zs)``, ``phase_sp_i = Zr theta_c / 2 pi - Zs psi_i / 2 pi`` (ring fixed,
    docs/conventions.md). Each windowed sample is added at that sun-tooth position; every planet
    contributes to the same average, so a local sun fault adds up coherently while what is not
    synchronous with the sun's teeth (other gears, noise) averages out (McFadden 1994).

    **Arguments:** as :func:`planet_separation`, with `z_sun`; `window_teeth` defaults to
    ``2 gcd(Zr, Zs)`` mesh periods (hann).

    **Returns:** :class:`SunAverage`.
    """
    sig, fs = as_signal(x, sample_rate, channel)
    zs, zr, n = int(z_sun), int(z_ring), int(n_planets)
    if min(zs, zr, n) < 1:
        raise RecordError(f"Zs, Zr and N must be positive integers, got {z_sun}, {z_ring}, {n_planets}")
    psi = (2 * np.pi * np.arange(n) / n if planet_angles is None
           else np.asarray(planet_angles, dtype=np.float64))
    if psi.shape != (n,):
        raise RecordError(f"planet_angles must hold {n} angles (rad), got {len(psi)}")
    g = math.gcd(zr, zs)
    width = float(window_teeth) if window_teeth is not None else (2.0 * g if window == "hann" else float(g))
    spt = int(samples_per_tooth)
    grid, xa = resample_to_angle(sig, fs, carrier_angle, zr * spt)
    n_bins = zs * spt
    num = np.zeros(n_bins)
    den = np.zeros(n_bins)
    passes = 0
    for i in range(n):
        w, n_pass = _passage_window(grid, psi[i], sensor_angle, zr, width, window)
        phase = (zr * grid - zs * psi[i]) / (2 * np.pi)  # sun-mesh cycles of planet i
        idx = np.mod(np.round(phase * spt).astype(np.int64), n_bins)
        num += np.bincount(idx, weights=w * xa, minlength=n_bins)
        den += np.bincount(idx, weights=w, minlength=n_bins)
        passes += n_pass
    avg = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
    return SunAverage(np.arange(n_bins) / spt, avg, den, int(passes))
