"""Residuals between a measured record and the twin: log-amplitude spectra robust to phase,
gain and noise.

A record is turned once into an :class:`Observation` (numpy, before any fit): its operating
point, the selected spectral points and their measured levels. The twin's signal is simulated
with the *same* rate, length, window and operating point, and the same operator picks the same
points, so the two feature vectors are matched point by point and have a fixed length (``vmap``
over parameter vectors, starts or records of one shape works).

**Features** (:class:`Features`):

- ``spectrum`` (steady records): the Hann amplitude spectrum of the whole record at the points of
  bands around every mesh harmonic ``h f_mesh`` below 0.45 × the rate (``harmonics`` limits
  them), each ``± sidebands × N f_carrier`` wide, so the sidebands, the sun-fault families
  ``h f_mesh ± k f_sun_fault/N ± f_carrier`` and the modulation by the planet pass are included,
  not only 450–550 Hz. With ``grid="hz"`` the points are the DFT bins; with ``grid="orders"``
  they are a fixed grid of input-speed orders (``order_step``), the spectrum linearly
  interpolated there: records at different speeds then give vectors of the same length and
  meaning. With ``f_max`` also given (the **order domain**), nothing of the observation's
  shapes or statics depends on the speed: the harmonics are those below 0.45 × the rate at
  `f_max`, the band half-widths are exact orders, the default step is one DFT bin at `f_max`,
  the solver's step limit is set for `f_max` and the twin starts in its steady state at the
  record's own (traced) speed — records of one length and rate at any speed up to `f_max`
  share one compiled fit and stack into one ``vmap`` (:func:`dtwin.identify.fit.fit_batch`).
- ``spectrogram`` (run-ups, coast-downs): Hann short-time amplitude spectra (``segment`` s,
  half overlap) over ``band`` (Hz); the twin follows the speed profile estimated from the record,
  so the same frame shows the same instant.
- ``envelope`` (optional, weight ``envelope_weight``): amplitude spectrum of the Hilbert envelope
  up to ``envelope_max_order`` orders of the input speed — the fault's repetition frequencies.

**Distance.** Per point ``r = w (log(sqrt((g A_model)² + F²) + F) - log(A_meas + F))`` with
``F`` the measured noise floor (running median of the measured amplitude,
:func:`dtwin.signal.spectrum.noise_floor`) added *before* the logarithm on both sides: lines far above
the floor compare in relative (dB-like) terms, bins at the floor compare floor to floor (bounded,
no ``log 0``), and the unknown phase of every line drops out because only amplitudes are
compared. The model side is the *expected* measured level: a line ``S`` in noise has on average
the power sum ``sqrt(S² + σ²)``, and for pure noise (Rayleigh amplitudes of median ``F``)
``E[log(R + F)] = log(2F)`` within 0.004 (Monte Carlo) — so noise-only bins carry no bias that
a larger fault or stiffer mesh could "explain" by filling them (without this term a fitted
severity came out 0.87 for a true 0.5 at 10 dB SNR).

**Gain.** ``gain="profile"`` (default when ``sensor_gain`` is not free): ``log g`` is the mean of
``log A_meas - log A_model`` over the points standing more than 20 dB above the floor, recomputed
at every evaluation (so it is profiled out of the fit, and its uncertainty is carried by the
Jacobian through this formula). ``gain="fixed"`` uses the twin's signal as it is (times a free
``sensor_gain`` when that is free).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from dtwin.errors import RecordError, SettingsError
from dtwin.model.motor.drive import DrivePart
from dtwin.model.motor.speed_source import SpeedProfile
from dtwin.signal.spectrum import analytic_signal, get_window, noise_floor
from dtwin.signal.units import quantity as unit_quantity
from dtwin.simulation.simulate import (
    DAQ,
    SolverOptions,
    acquire,
    daq_grid,
    initial_state,
    integrate_observables,
    step_limit,
)

from .operating_point import gear_orders

__all__ = ["Features", "Observation", "model_signal", "observe", "observation_residuals",
           "quantity_of_unit", "MIN_SIDEBAND_BINS", "MIN_RATE_PER_MESH"]

#: Residual value substituted for a failed (NaN) simulation: a huge loss the solver rejects.
FAILED_RESIDUAL = 30.0

#: The record must hold the carrier sidebands this many DFT bins apart (Hann main lobe
#: half-width = 2 bins: two lines f_carrier apart are then resolved): T ≥ 2 / f_carrier.
MIN_SIDEBAND_BINS = 2.0
#: Sampling rate per mesh frequency (Nyquist × anti-alias margin, as dtwin.io.validate).
MIN_RATE_PER_MESH = 2.5
_STRONG_DB = 20.0


def quantity_of_unit(unit: str) -> str:
    """The twin's DAQ quantity for a record channel unit (``m/s^2``, ``g`` → acceleration,
    ``mm/s`` → velocity, ``um`` → displacement: `dtwin.signal.units.quantity`); units that
    do not say (``V``) are taken as acceleration (the gain absorbs the scale)."""
    return unit_quantity(unit) or "acceleration"


@dataclasses.dataclass(frozen=True)
class Features:
    """What the residuals compare (module docstring). All fields optional.

    - `kind`: ``spectrum`` or ``spectrogram`` (default ``spectrum``; ``spectrogram`` for ramps).
    - `harmonics`: highest mesh harmonic used (None: all below 0.45 × the rate).
    - `sidebands`: half-width of each band in units of the planet-pass spacing ``N f_carrier``.
    - `grid`: ``hz`` (DFT bins) or ``orders`` (fixed order grid, step `order_step`).
    - `order_step`: step of the order grid (orders of the input speed; None: one bin at the
      record's speed, or at `f_max` when given).
    - `f_max` (Hz): with ``grid="orders"``, the highest input speed the fit serves: shapes and
      statics then follow only the record's length, rate and the order grid (module docstring:
      the order domain). Spectrum features only, no envelope term.
    - `segment` (s), `band` (Hz, None: 0.5 f_mesh … 0.45 × rate): spectrogram settings.
    - `floor_bins`: running-median width of the noise floor (bins).
    - `envelope_weight`, `envelope_max_order`: the envelope-spectrum term (0 = off).
    - `gain`: ``profile`` or ``fixed``.
    """

    kind: str = "spectrum"
    harmonics: int | None = None
    sidebands: float = 4.0
    grid: str = "hz"
    order_step: float | None = None
    segment: float = 0.04
    band: tuple[float, float] | None = None
    floor_bins: int = 31
    envelope_weight: float = 0.0
    envelope_max_order: float = 12.0
    gain: str = "profile"
    f_max: float | None = None

    def __post_init__(self):
        if self.kind not in ("spectrum", "spectrogram"):
            raise SettingsError(f"Features.kind must be spectrum or spectrogram, got {self.kind!r}")
        if self.grid not in ("hz", "orders"):
            raise SettingsError(f"Features.grid must be hz or orders, got {self.grid!r}")
        if self.gain not in ("profile", "fixed"):
            raise SettingsError(f"Features.gain must be profile or fixed, got {self.gain!r}")
        if self.f_max is not None:
            if self.grid != "orders" or self.kind != "spectrum" or self.envelope_weight > 0:
                raise SettingsError("Features.f_max (the order domain) needs grid='orders', "
                                 "kind='spectrum' and no envelope term")
            if not self.f_max > 0:
                raise SettingsError(f"Features.f_max must be > 0 Hz, got {self.f_max!r}")

    @property
    def order_domain(self) -> bool:
        """Whether the observation's shapes and statics are independent of the speed."""
        return self.f_max is not None


class Observation(eqx.Module):
    """One record, prepared for fitting (see :func:`observe`).

    Static: `sample_rate` (Hz), `n_samples`, `quantity`, `f_ref` (Hz, the input speed rounded to
    0.1 Hz: sets the solver's step limit and initial state only, so records whose speeds differ
    slightly share one compiled fit), `ramp` (a run-up/coast-down), `kind`,
    `segment_len`, `gain_mode`, `env_weight`, `weight`, `discard` (s of model transient),
    `oversample`, `order_domain` (``Features.f_max`` given: `f_ref` is that `f_max`, and the
    steady initial state is taken at the traced `speed` instead).
    Arrays: `speed` (Hz, (start, end) of the input speed over the record; equal for a steady
    record), `k`, `w` (points: bin index and interpolation weight), `meas` (log measured level),
    `floor` (linear floor), `strong` (1 where the measured point stands 20 dB above the floor),
    `group` (band number per point, for the correlation of neighbours), and the same for the
    envelope (`env_k`, `env_meas`, `env_floor`); `noise` (spectrograms: the white-noise
    amplitude's starting value, profiled at every evaluation, :func:`profiled_noise`; None:
    the measured floor stands for the noise).
    """

    sample_rate: float = eqx.field(static=True)
    n_samples: int = eqx.field(static=True)
    quantity: str = eqx.field(static=True)
    f_ref: float = eqx.field(static=True)
    ramp: bool = eqx.field(static=True)
    kind: str = eqx.field(static=True)
    segment_len: int = eqx.field(static=True)
    gain_mode: str = eqx.field(static=True)
    env_weight: float = eqx.field(static=True)
    weight: float = eqx.field(static=True)
    discard: float = eqx.field(static=True)
    oversample: int = eqx.field(static=True)
    speed: jax.Array
    k: jax.Array
    w: jax.Array
    meas: jax.Array
    floor: jax.Array
    strong: jax.Array
    group: jax.Array
    freqs: jax.Array
    env_k: jax.Array
    env_meas: jax.Array
    env_floor: jax.Array
    frf_hz: tuple[float, ...] | None = eqx.field(static=True, default=None)
    frf_db: tuple[float, ...] | None = eqx.field(static=True, default=None)
    noise: jax.Array | None = None
    order_domain: bool = eqx.field(static=True, default=False)

    @property
    def duration(self) -> float:
        return self.n_samples / self.sample_rate

    @property
    def size(self) -> int:
        return int(self.meas.shape[0]) + (int(self.env_meas.shape[0]) if self.env_weight else 0)


# ------------------------------------------------------------------------------- transforms
def _window(n: int) -> np.ndarray:
    return get_window("hann", n)


def _amplitude(x, n: int):
    """Hann amplitude spectrum (dtwin.signal.spectrum scaling), numpy or JAX, last axis."""
    xp = jnp if isinstance(x, jax.Array) else np
    w = _window(n)
    spec = xp.abs(xp.fft.rfft((x - xp.mean(x, axis=-1, keepdims=True)) * xp.asarray(w), axis=-1))
    return spec * (2.0 / w.sum())


def _frames(n: int, seg: int) -> np.ndarray:
    hop = seg // 2
    starts = np.arange(0, n - seg + 1, hop)
    return starts[:, None] + np.arange(seg)[None, :]


def _feature_amplitude(x, obs_kind: str, n: int, seg: int):
    """The linear amplitudes (flattened) that the points `k` index."""
    if obs_kind == "spectrum":
        return _amplitude(x, n)
    idx = _frames(n, seg)
    return _amplitude(x[idx], seg).reshape(-1)


def _envelope(x, n: int):
    xp = jnp if isinstance(x, jax.Array) else np
    env = xp.abs(analytic_signal(x - xp.mean(x)))
    return _amplitude(env, n)


# ------------------------------------------------------------------------------- observe
#: Rayleigh median over its 10 % quantile: sqrt(2 ln 2) / sqrt(-2 ln 0.9).
_Q10_TO_MEDIAN = math.sqrt(2 * math.log(2)) / math.sqrt(-2 * math.log(0.9))


def _stationary_floor(amp2: np.ndarray, floor_bins: int) -> np.ndarray:
    """Noise floor of a short-time spectrum ``(frames, bins)``, the same in every frame: per bin
    the 10 % quantile over the frames (Rayleigh-scaled to the median), smoothed by a running
    median over frequency. The running median of each frame alone counts a fault's broadband
    impacts (present in every 40 ms frame) as noise, and the model side then adds them twice:
    measured on a 0.5 s run-up at 25.6 kHz, 10 dB SNR, that floor was 10 % (median) to 40 %
    (90th percentile) above the true noise's and the loss preferred severity 0.3 to the true 0.5;
    with the noise-only floor the loss is least at the truth."""
    q = np.quantile(amp2, 0.1, axis=0) * _Q10_TO_MEDIAN
    return np.broadcast_to(noise_floor(q, floor_bins), amp2.shape)


def _check(record, twin, f_sun: float, channel) -> np.ndarray:
    orders = gear_orders(twin)
    x = np.asarray(record.channel(channel), dtype=np.float64)
    bad = ~np.isfinite(x)
    if bad.any():
        raise RecordError(
            f"record channel {channel!r} holds {int(bad.sum())} NaN/inf samples (first at sample "
            f"{int(np.flatnonzero(bad)[0])}); clean or cut the record before identification"
        )
    fs = float(record.sample_rate)
    f_mesh = orders["mesh"] * f_sun
    if fs < MIN_RATE_PER_MESH * f_mesh:
        raise RecordError(
            f"sample rate {fs:g} Hz is below {MIN_RATE_PER_MESH} × the mesh frequency "
            f"({f_mesh:.1f} Hz at {f_sun:.2f} Hz input speed): the mesh line is not resolved; "
            f"record at ≥ {MIN_RATE_PER_MESH * f_mesh:.0f} Hz"
        )
    f_c = orders["carrier"] * f_sun
    need = MIN_SIDEBAND_BINS / f_c
    if record.duration < need:
        raise RecordError(
            f"record of {record.duration:.3g} s is too short to resolve the carrier sidebands "
            f"(f_carrier = {f_c:.2f} Hz needs ≥ {MIN_SIDEBAND_BINS:g}/f_carrier = {need:.3g} s); "
            "use a longer record"
        )
    return x


def _spectrum_points(x, fs, duration, twin, orders, feats, f_sun, f_round, f_mesh, spacing):
    """The fitted points of a spectrum (``Features.kind == "spectrum"``): every mesh harmonic
    below 0.45 `fs` with its carrier sidebands, on the record's bins or on an order grid.
    **Returns** ``(k, w, a_meas, floor, group, freqs)``: bin and interpolation weight of each
    point, measured amplitude and noise floor there, harmonic number, frequency (Hz)."""
    n = x.size
    amp = _amplitude(x, n)
    freqs = np.fft.rfftfreq(n, 1.0 / fs)
    floor_all = noise_floor(amp, feats.floor_bins)
    hmax = int(np.floor(0.45 * fs / (f_mesh + feats.sidebands * spacing)))
    if feats.harmonics is not None:
        hmax = min(hmax, int(feats.harmonics))
    if hmax < 1:
        raise RecordError("no mesh harmonic band fits below 0.45 × the sample rate")
    pts, grp = [], []
    half = feats.sidebands * spacing / f_sun  # orders
    if feats.order_domain:
        half = feats.sidebands * twin.lp.n_planets * orders["carrier"]  # exact orders
    step = feats.order_step or 1.0 / (duration * f_round)
    for h in range(1, hmax + 1):
        c = h * orders["mesh"]
        if feats.grid == "orders":
            o = c + np.arange(-np.floor(half / step), np.floor(half / step) + 1) * step
            fpts = o * f_sun
        else:
            nb = int(np.floor(half * f_round * duration))
            centre = int(round(c * f_sun * duration))
            sel = np.clip(np.arange(centre - nb, centre + nb + 1), 0, freqs.size - 1)
            fpts = freqs[sel]
        pts.append(fpts)
        grp.append(np.full(fpts.size, h))
    fpts = np.concatenate(pts)
    group = np.concatenate(grp)
    pos = fpts / (fs / n)
    k = np.clip(np.floor(pos).astype(np.int64), 0, amp.size - 2)
    w = np.clip(pos - k, 0.0, 1.0)
    a_meas = (1 - w) * amp[k] + w * amp[k + 1]
    floor = (1 - w) * floor_all[k] + w * floor_all[k + 1]
    return k, w, a_meas, floor, group, fpts


def _spectrogram_points(x, fs, orders, feats, f_sun, f_end):
    """The fitted points of a spectrogram (``Features.kind == "spectrogram"``): every bin of
    the band in every frame. **Returns** ``(seg, k, w, a_meas, floor, group, freqs)``, `seg`
    the frame length (samples), `group` the frame number."""
    n = x.size
    seg = int(round(feats.segment * fs))
    seg += seg % 2
    if seg > n // 2:
        raise RecordError(f"spectrogram segment {feats.segment} s is longer than half the record")
    frames = _frames(n, seg)
    amp2 = _amplitude(x[frames], seg)  # (frames, bins)
    floor2 = _stationary_floor(amp2, feats.floor_bins)
    freqs = np.fft.rfftfreq(seg, 1.0 / fs)
    lo, hi = feats.band or (0.5 * orders["mesh"] * min(f_sun, f_end or f_sun), 0.45 * fs)
    sel = np.flatnonzero((freqs >= lo) & (freqs <= hi))
    if sel.size == 0:
        raise RecordError(f"spectrogram band {lo:.0f}–{hi:.0f} Hz holds no bin")
    nb = freqs.size
    k = (np.arange(frames.shape[0])[:, None] * nb + sel[None, :]).reshape(-1)
    w = np.zeros(k.size)
    a_meas = amp2.reshape(-1)[k]
    floor = floor2.reshape(-1)[k]
    group = np.repeat(np.arange(frames.shape[0]), sel.size)
    pfreqs = np.tile(freqs[sel], frames.shape[0])
    return seg, k, w, a_meas, floor, group, pfreqs


def _envelope_points(x, fs, feats, f_hi):
    """The envelope spectrum's bins up to ``Features.envelope_max_order`` × `f_hi` (Hz), their
    log levels and floor; empty when the envelope is not weighted."""
    n = x.size
    if not feats.envelope_weight > 0:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    env = _envelope(x, n)
    efreqs = np.fft.rfftfreq(n, 1.0 / fs)
    env_k = np.flatnonzero((efreqs > 0) & (efreqs <= feats.envelope_max_order * f_hi))
    efloor = noise_floor(env, feats.floor_bins)[env_k]
    return env_k, np.log(env[env_k] + efloor), efloor


def observe(
    record,
    twin,
    *,
    f_sun: float,
    f_end: float | None = None,
    features: Features | None = None,
    channel: int | str = 0,
    weight: float = 1.0,
    discard: float = 0.05,
    oversample: int = 4,
) -> Observation:
    """Prepare one record for fitting: checks, points, measured levels, floor.

    **Arguments:**

    - `record`: a `dtwin.io.Record`; `twin`: the fitted twin (tooth numbers).
    - `f_sun`: input speed (Hz) from :mod:`dtwin.identify.operating_point` (the ramp's start for a
      run-up); `f_end`: the ramp's end (Hz), None for a steady record.
    - `features`: :class:`Features`; `channel`; `weight`: this record's weight in a joint fit.
    - `discard` (s): transient the twin simulates before the record starts; `oversample`: the
      twin's DAQ oversampling.

    **Raises:** `RecordError` for NaN/inf, a rate under 2.5 f_mesh, a record shorter than
    ``MIN_SIDEBAND_BINS / f_carrier`` or an empty band — before any simulation.
    """
    feats = features or Features(kind="spectrum" if f_end is None else "spectrogram")
    x = _check(record, twin, f_sun if f_end is None else min(f_sun, f_end), channel)
    if f_end is not None:
        _check(record, twin, max(f_sun, f_end), channel)
    fs = float(record.sample_rate)
    n = x.size
    orders = gear_orders(twin)
    f_hi = max(f_sun, f_end or f_sun)
    # shapes follow the speed rounded to 0.1 Hz, so nearby speeds give equal shapes
    f_round = round(float(f_sun), 1)
    if feats.order_domain:
        if f_end is not None:
            raise SettingsError("Features.f_max (the order domain) is for steady records")
        if f_sun > feats.f_max * (1 + 1e-9):
            raise RecordError(f"input speed {f_sun:.4g} Hz is above Features.f_max = "
                              f"{feats.f_max:g} Hz; raise f_max")
        # every static below follows f_max, not the speed
        f_round = float(feats.f_max)
    f_mesh = orders["mesh"] * f_round
    spacing = twin.lp.n_planets * orders["carrier"] * f_round
    if feats.kind == "spectrum":
        seg = n
        k, w, a_meas, floor, group, pfreqs = _spectrum_points(
            x, fs, record.duration, twin, orders, feats, f_sun, f_round, f_mesh, spacing)
    else:
        seg, k, w, a_meas, floor, group, pfreqs = _spectrogram_points(
            x, fs, orders, feats, f_sun, f_end)
    strong = (a_meas > floor * 10 ** (_STRONG_DB / 20)).astype(np.float64)
    env_k, env_meas, efloor = _envelope_points(x, fs, feats, f_hi)
    f_ref = round(float(f_sun) - (0.0 if f_end is None else
                                  (f_end - f_sun) / record.duration * discard), 1)
    return Observation(
        sample_rate=fs, n_samples=n, quantity=quantity_of_unit(record.units[record.index(channel)]),
        f_ref=float(feats.f_max) if feats.order_domain else f_ref,
        ramp=f_end is not None, kind=feats.kind,
        speed=jnp.asarray([float(f_sun), float(f_sun if f_end is None else f_end)]),
        segment_len=int(seg), gain_mode=feats.gain, env_weight=float(feats.envelope_weight),
        weight=float(weight), discard=float(discard), oversample=int(oversample),
        k=jnp.asarray(k), w=jnp.asarray(w), meas=jnp.asarray(np.log(a_meas + floor)),
        floor=jnp.asarray(floor), strong=jnp.asarray(strong), group=jnp.asarray(group),
        freqs=jnp.asarray(pfreqs), env_k=jnp.asarray(env_k), env_meas=jnp.asarray(env_meas),
        env_floor=jnp.asarray(efloor),
        noise=(None if feats.kind == "spectrum"
               else jnp.asarray(float(np.quantile(a_meas, 0.1)) * _Q10_TO_MEDIAN)), order_domain=feats.order_domain,
    )


# ------------------------------------------------------------------------------- model side
def drive_at(twin, f_start, f_end=None, duration: float | None = None, discard: float = 0.0):
    """`twin` with its drive's speed set point replaced: constant `f_start` (Hz), or a linear
    ramp reaching `f_start` at ``t = discard`` (the first recorded sample) and `f_end` at
    ``discard + duration`` (a run-up record as :func:`dtwin.identify.residuals.observe` sees it).
    Values may be JAX arrays (traced)."""
    idx = [i for i, p in enumerate(twin.parts) if isinstance(p, DrivePart)]
    if not idx:
        return twin
    i = idx[0]
    two_pi = 2.0 * math.pi
    f0 = jnp.asarray(f_start, dtype=jnp.float64)
    if f_end is None:
        prof = SpeedProfile("constant", two_pi * f0, two_pi * f0, jnp.zeros(()), jnp.zeros(()))
    else:
        f1 = jnp.asarray(f_end, dtype=jnp.float64)
        slope = (f1 - f0) / duration
        start = f0 - slope * discard
        prof = SpeedProfile("ramp", two_pi * start, two_pi * f1, jnp.zeros(()),
                            jnp.asarray(duration + discard, dtype=jnp.float64))
    return eqx.tree_at(lambda t: t.parts[i].drive.speed, twin, prof)


def _with_speed(twin, obs: Observation):
    """The twin driven at the observation's speed (constant, or the ramp)."""
    if not obs.ramp:
        return drive_at(twin, obs.speed[0])
    return drive_at(twin, obs.speed[0], obs.speed[1], obs.duration, obs.discard)


def _start_speed(obs: Observation) -> float:
    """Static speed (Hz) for the solver's step limit and steady initial state."""
    return obs.f_ref


def _simulate_jittable(twin, *, duration, f_sun, daq, discard, solver, f_init=None):
    """`dtwin.simulation.simulate.simulate` for use inside `jit`/`vmap`/`jacfwd`: the same pipeline
    (steady start, Tsit5 with the sensor computed inside the model, DAQ FIR + decimation) with
    the time grid built in numpy — `simulate` itself converts a jnp grid with `float()`, which
    fails on tracers. `f_sun` (static, Hz) sets the step limit; the steady initial state is
    taken at `f_init` (Hz, may be traced) when given, else at `f_sun`. **Returns**
    ``(signal, defect)``, `defect` the periodicity defect of a tiled response (None when
    integrated in full; `dtwin.simulation.simulate.SimResult.periodic_defect`)."""
    fs_out = float(daq.sample_rate)
    fs_hi, taps, ts_np = daq_grid(duration, discard, daq)
    t0 = float(ts_np[0])
    y0 = initial_state(twin, f_sun if f_init is None else f_init, "steady")
    dtmax = step_limit(twin, f_sun, solver)
    # in full, or over one period of the gear set when `solver.periodic` allows (dtwin.simulate)
    ys, _, nsteps, _, defect = integrate_observables(twin, y0, t0, ts_np, fs_hi, f_sun,
                                                     daq.quantity, solver, dtmax)
    sig = acquire(ys, taps, daq, fs_out, nsteps, 0, float(discard)).signal
    return sig, defect


def model_signal(twin, obs: Observation, solver=None):
    """The twin's sensor signal for `obs` (same rate, length, quantity and speed), JAX."""
    return model_signal_and_defect(twin, obs, solver)[0]


def model_signal_and_defect(twin, obs: Observation, solver=None):
    """``(signal, defect)``: :func:`model_signal` and the periodicity defect of a tiled response
    (relative rms difference of the signal as integrated and as tiled over a probe window,
    `dtwin.simulation.simulate.SimResult.periodic_defect`), None where the record is integrated in full.
    JAX."""
    solver = solver or SolverOptions()
    daq = DAQ(sample_rate=obs.sample_rate, oversample=obs.oversample, quantity=obs.quantity,
              frf_hz=obs.frf_hz, frf_db=obs.frf_db)
    f_init = obs.speed[0] if obs.order_domain else None
    sig, defect = _simulate_jittable(_with_speed(twin, obs), duration=obs.duration,
                                     f_sun=_start_speed(obs), daq=daq, discard=obs.discard,
                                     solver=solver, f_init=f_init)
    n = obs.n_samples
    return (sig[:n] if sig.shape[0] >= n else jnp.pad(sig, (0, n - sig.shape[0]))), defect


def model_amplitudes(signal, obs: Observation):
    """Linear amplitudes of the model at the observation's points (and envelope points)."""
    amp = _feature_amplitude(signal, obs.kind, obs.n_samples, obs.segment_len)
    a = (1.0 - obs.w) * amp[obs.k] + obs.w * amp[jnp.minimum(obs.k + 1, amp.shape[0] - 1)]
    if obs.env_weight:
        env = _envelope(signal, obs.n_samples)[obs.env_k]
    else:
        env = jnp.zeros(0)
    return a, env


def profiled_log_gain(a_model, obs: Observation):
    """``log g``: mean over the strong points of ``log(A_meas + F) - log(A_model + F)`` (≈ the
    log ratio of the two amplitudes there, module docstring)."""
    diff = obs.meas - jnp.log(a_model + obs.floor)
    ns = jnp.maximum(jnp.sum(obs.strong), 1.0)
    return jnp.sum(obs.strong * diff) / ns


def _noisy_log(a, floor):
    """Expected ``log(|S + N| + F)`` of a line of amplitude `a` in noise of median floor `F`:
    ``log(sqrt(a² + F²) + F)`` (module docstring)."""
    return jnp.log(jnp.sqrt(a * a + floor * floor) + floor)


def profiled_noise(a_model, obs: Observation, iterations: int = 4):
    """White-noise amplitude ``ν`` (median of the noise's Rayleigh amplitude) that best explains
    the measured levels with the model's: Gauss–Newton in ``log ν`` on
    ``Σ (log(sqrt(a² + ν²) + F) - log(A_meas + F))²``, from `obs.noise`, unrolled (so the
    Jacobian carries its dependence on the parameters).

    Why (spectrograms): in 40 ms frames a fault's impacts spread broadband content over every
    bin of every frame, so the measured running median ``F`` is not the noise: used as the
    noise in the model's expected level it counts that content twice (measured on a 0.5 s
    run-up at 25.6 kHz, 10 dB SNR: ``F`` 10 % (median) to 40 % (90th percentile) above the
    noise-only floor, and the loss preferred severity 0.3 to the true 0.5). A sensor's noise
    is white over the band, one number the many noise-dominated points determine."""
    u = jnp.log(obs.noise)
    a2 = a_model * a_model
    for _ in range(iterations):
        nu2 = jnp.exp(2 * u)
        root = jnp.sqrt(a2 + nu2)
        r = jnp.log(root + obs.floor) - obs.meas
        d = nu2 / (root * (root + obs.floor))
        u = u - jnp.sum(r * d) / jnp.maximum(jnp.sum(d * d), 1e-30)
    return jnp.exp(u)


def _expected_log(ga, obs: Observation):
    if obs.noise is None:
        return _noisy_log(ga, obs.floor)
    nu = profiled_noise(ga, obs)
    return jnp.log(jnp.sqrt(ga * ga + nu * nu) + obs.floor)


def observation_residuals(signal, obs: Observation, gain=1.0):
    """Residual vector of one observation for a model `signal` (module docstring)."""
    a, env = model_amplitudes(signal, obs)
    a = gain * a
    if obs.gain_mode == "profile":
        g = jnp.exp(profiled_log_gain(a, obs))
    else:
        g = jnp.ones(())
    r = obs.weight * (_expected_log(g * a, obs) - obs.meas)
    if obs.env_weight:
        re = obs.weight * obs.env_weight * (_noisy_log(g * gain * env, obs.env_floor)
                                            - obs.env_meas)
        r = jnp.concatenate([r, re])
    return r


def residual_count(obs: Observation) -> int:
    """Length of :func:`observation_residuals`' vector for `obs` (points, then envelope)."""
    return int(obs.meas.shape[0]) + (int(obs.env_meas.shape[0]) if obs.env_weight else 0)


def levels_from_residuals(r, obs: Observation):
    """:func:`fitted_levels` read back from `obs`'s residual vector `r` (numpy, as
    :func:`observation_residuals` made it): its first entries are ``weight (log fitted − log
    measured)`` at the points. None when `r` cannot give them (wrong length, a zero weight, a
    point whose model value was not finite and was replaced by :data:`FAILED_RESIDUAL`)."""
    meas = np.asarray(obs.meas, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    if r.shape[0] != residual_count(obs) or not obs.weight > 0.0:
        return None
    rp = r[: meas.shape[0]]
    if not np.all(np.isfinite(rp)) or np.any(rp == FAILED_RESIDUAL):
        return None
    return np.exp(meas + rp / obs.weight), np.exp(meas)


def fitted_levels(signal, obs: Observation, gain=1.0):
    """Model and measured amplitude (linear, floor added) at the points, numpy: for figures."""
    a, _ = model_amplitudes(signal, obs)
    a = gain * a
    g = jnp.exp(profiled_log_gain(a, obs)) if obs.gain_mode == "profile" else 1.0
    return np.asarray(jnp.exp(_expected_log(g * a, obs))), np.exp(np.asarray(obs.meas))


#: DFT bins each side of a bin over which a Hann window spreads its noise (the window's
#: transform has three non-zero taps on the bin grid).
HANN_REACH_BINS = 2


def window_reach(observations: Sequence[Observation]) -> int:
    """Points of one group farther apart than this share no noise through the Hann window
    (:data:`HANN_REACH_BINS` DFT bins, in points of each observation's grid; one more where
    the points are interpolated between bins); the largest over `observations`
    (:func:`dtwin.identify.uncertainty.residual_whiteness`)."""
    out = HANN_REACH_BINS
    for o in observations:
        bin_hz = o.sample_rate / (o.n_samples if o.kind == "spectrum" else o.segment_len)
        f, g = np.asarray(o.freqs), np.asarray(o.group)
        step = np.diff(f)[(g[1:] == g[:-1]) & (np.diff(f) > 0)]
        if step.size == 0:
            continue
        reach = math.ceil(HANN_REACH_BINS * bin_hz / float(np.median(step)) - 1e-9)
        if np.any(np.asarray(o.w) > 1e-6):  # linear interpolation shares a bin between points
            reach += 1
        out = max(out, reach)
    return out


def point_groups(observations: Sequence[Observation]) -> np.ndarray:
    """Group id per residual (band, frame or envelope of each record): neighbouring points of
    one group are correlated (window leakage), different groups are not."""
    out, off = [], 0
    for o in observations:
        g = np.asarray(o.group)
        out.append(g + off)
        off += int(g.max(initial=0)) + 1
        if o.env_weight:
            out.append(np.full(o.env_meas.shape[0], off))
            off += 1
    return np.concatenate(out) if out else np.zeros(0, np.int64)
