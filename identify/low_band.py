"""The low band: a steady record's spectrum below its first mesh band, added to an observation.

The residuals of :mod:`dtwin.identify.residuals` look at bands around the mesh harmonics. Below
the first of them a local tooth fault makes its strongest lines: the comb of the faulty tooth's
passes (``k f_sf``; with ``± f_s`` for a sun fault when the sun floats on its bearing), tens of
dB above the floor where its mesh sidebands stand a few. :func:`with_low_band` adds every DFT
bin from ``LOW_BAND_START × N f_c`` (the lowest knot of a calibrated sensor response) up to the
first mesh band to an observation as band 0; :func:`with_low_band_problem` does so for each
observation of a fit's problem. A severity fit uses it (:mod:`dtwin.identify.severity`, "The
low band"), and so does the scoring of a calibration's excitation/response splits
(:func:`dtwin.identify.excitation_response.low_band_losses`). Frequencies in Hz.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from dtwin.errors import SettingsError
from dtwin.model.kinematics import Kinematics
from dtwin.signal.spectrum import noise_floor

from .residuals import _STRONG_DB, _amplitude

__all__ = ["LOW_BAND_LOCATIONS", "LOW_BAND_START", "lowest_knot", "with_low_band",
           "with_low_band_problem"]

#: Start of the low band (units of the planet-pass frequency ``N f_c``): the lowest knot of a
#: calibrated sensor response (:mod:`dtwin.identify.calibrate`).
LOW_BAND_START = 0.8

def lowest_knot(kin) -> float:
    """``LOW_BAND_START × N f_c`` (Hz) for a gearbox's kinematics `kin`: the lowest knot of a
    calibrated sensor response, where the low band and the gap
    (:func:`dtwin.identify.gap.named_bands`, ``f_min``) start."""
    return LOW_BAND_START * kin.n_planets * kin.f_carrier


#: Fault locations whose severity fits the low band by default (``low_band=None``): the sun's
#: and the ring's low comb lies where the records put it; a planet fault's the twin places
#: beside ``k f_p`` (docs/identification.md, "The low band").
LOW_BAND_LOCATIONS = ("sun", "ring")


def with_low_band(obs, record, *, channel: int | str = 0, floor_bins: int = 31,
                  start: float = LOW_BAND_START, n_planets: int = 3, f_carrier: float):
    """`obs` (a steady spectrum :class:`dtwin.identify.residuals.Observation`) with the low band
    added as band 0: every DFT bin from ``start × N f_c`` (Hz) up to the first mesh band, with
    its measured level and noise floor computed as :func:`dtwin.identify.residuals.observe`
    does. A local tooth fault's strongest lines at a low sampling rate lie there: the impulse
    comb of the faulty tooth's passes (``k f_sf``), with the sun's rotation ``± f_s`` when the
    sun floats (:mod:`dtwin.identify.severity`, "The low band")."""
    if obs.kind != "spectrum" or obs.ramp or obs.order_domain:
        raise SettingsError("the low band is for steady spectrum observations (grid='hz')")
    x = np.asarray(record.channel(channel), dtype=np.float64)[: obs.n_samples]
    amp = np.asarray(_amplitude(x, obs.n_samples))
    floor_all = noise_floor(amp, floor_bins)
    freqs = np.fft.rfftfreq(obs.n_samples, 1.0 / obs.sample_rate)
    f_hi = float(np.min(np.asarray(obs.freqs)))
    sel = np.flatnonzero((freqs >= start * n_planets * f_carrier) & (freqs < f_hi))
    if sel.size == 0:
        return obs
    a, fl = amp[sel], floor_all[sel]
    strong = (a > fl * 10 ** (_STRONG_DB / 20)).astype(np.float64)
    cat = lambda new, old: jnp.concatenate([jnp.asarray(new, dtype=jnp.asarray(old).dtype),  # noqa: E731
                                            jnp.asarray(old)])
    return dataclasses.replace(
        obs, k=cat(sel, obs.k), w=cat(np.zeros(sel.size), obs.w),
        meas=cat(np.log(a + fl), obs.meas), floor=cat(fl, obs.floor),
        strong=cat(strong, obs.strong), group=cat(np.zeros(sel.size), obs.group),
        freqs=cat(freqs[sel], obs.freqs))


def with_low_band_problem(problem, records, *, channel: int | str = 0):
    """`problem` with the low band (:func:`with_low_band`) added to the observation of each of
    `records` (one per observation, in order; a single record for the first observation alone),
    at the planet-pass frequency of each observation's speed."""
    recs = list(records) if isinstance(records, (list, tuple)) else [records]
    lp = problem.twin.lp
    new = tuple(with_low_band(o, rec, channel=channel, n_planets=int(lp.n_planets),
                              f_carrier=Kinematics.from_gear_set(lp, float(o.speed[0])).f_carrier)
                for o, rec in zip(problem.observations, recs, strict=False))
    return dataclasses.replace(problem, observations=new + problem.observations[len(new):])
