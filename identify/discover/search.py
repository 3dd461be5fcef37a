"""What a discrepancy search holds fixed and what its steps change.

:class:`Search` is the record's side of a run (:func:`open_search`): the record cut to whole
folds, the speed and kinematics, the DAQ, the whole-record and fold spectra, and the held-out
gaps of a model against them, with the model's gain to the record (:func:`_log_gain`).
:class:`State` is what the steps change: the candidates, the
extended model about them, the current model signal and parameters, and what was added.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from dtwin.io.record import Record
from dtwin.signal.spectrum import amplitude_spectrum, as_signal, noise_floor
from dtwin.signal.units import quantity as unit_quantity
from dtwin.spec import Spec, load_spec
from dtwin.spec.build import daq_from_spec

from ..gap import FLOOR_BINS, gap, named_bands, segment_spectra
from ..lines import Kinematics, band_bounds, chance_match_probability
from ..low_band import lowest_knot
from ..operating_point import resolve_speed
from .effects.base import EffectContext
from .model import ExtendedModel
from .results import Step
from .settings import DiscoverySettings
from .statistics import chi2_quantile, normal_quantile


def _log_gain(Y, Z0, floor, thr_db, n_lines: int = 20) -> float:
    """Log of the gain that scales the model's amplitude `Z0` to the measured `Y`: the median
    log ratio over the bins where both stand `thr_db` over the floor, started from the model's
    `n_lines` strongest lines and iterated (three passes). Starting from every bin where the
    measurement has a line would let lines the model lacks (a fault's comb, where the model
    holds only numerical leakage) set the gain (benchmarks/README.md, "Moved from module
    docstrings")."""
    a0 = np.abs(Z0)
    if not np.any(a0 > 0):
        return 0.0
    thr = floor * 10 ** (thr_db / 20.0)
    pk = np.flatnonzero((a0[1:-1] >= a0[:-2]) & (a0[1:-1] >= a0[2:]) & (a0[1:-1] > 0)) + 1
    if pk.size == 0:
        return 0.0
    pk = pk[np.argsort(a0[pk])[::-1][:n_lines]]
    g = float(np.median(np.log(np.maximum(Y[pk], 1e-300) / a0[pk])))
    for _ in range(3):
        sel = (Y > thr) & (np.exp(g) * a0 > thr)
        if not sel.any():
            break
        g = float(np.median(np.log(Y[sel] / a0[sel])))
    return g


@dataclasses.dataclass(eq=False)
class Search:
    """The fixed inputs of one search (:func:`open_search`)."""

    spec: Spec
    settings: DiscoverySettings
    say: Callable[[str], None]
    #: the record, cut to a multiple of ``2 n_folds`` samples, mean removed
    x: np.ndarray
    fs: float
    kin: Kinematics
    f_sun: float
    f_max: float
    daq: object
    #: whole-record Hann spectrum (frequencies as computed; amplitudes as a NumPy array)
    freqs_full: object
    a_full: np.ndarray
    #: fold spectra of the record: frequencies, amplitudes (F, K), noise floor
    freqs: np.ndarray
    Y: np.ndarray
    floor: np.ndarray
    #: the named bands of the gap from `f_lo` to the DAQ's pass band
    #: (:func:`dtwin.identify.gap.named_bands`)
    bands: dict
    #: the bottom of the scored band (Hz): the lowest knot of a calibrated sensor response
    #: (:func:`dtwin.identify.low_band.lowest_knot`)
    f_lo: float
    #: the line tolerance (Hz) on the whole-record spectrum
    tol_full: float
    chance: float
    #: lines the calibration left unexplained on the healthy records (dtwin.identify.shortfall)
    shortfall_orders: list
    #: the level of the parameter intervals (normal quantile) and of identification (χ²₁)
    z: float
    chi2: float

    @property
    def n(self) -> int:
        return len(self.x)

    @property
    def df(self):
        return self.freqs[1] - self.freqs[0]

    @property
    def nb(self) -> int:
        return len(self.freqs)

    @property
    def seg_len(self) -> int:
        return self.n // self.settings.n_folds

    def fold_gains(self, Z0) -> np.ndarray:
        """Each fold's log gain of the model spectra `Z0` (F, K) to the record's."""
        return np.array([_log_gain(self.Y[f], Z0[f], self.floor[f], self.settings.threshold_db)
                         for f in range(self.settings.n_folds)])

    def search_gap(self, a_model_folds):
        """The search's held-out gap: bins `threshold_db` over the floor (its decisions)."""
        return gap(self.freqs, self.Y, a_model_folds, self.bands, self.floor,
                   self.settings.threshold_db)

    def reported_gap(self, a_model_folds):
        """The held-out gap as reported (`gap_threshold_db`; None: family-wise, as calibration's)."""
        return gap(self.freqs, self.Y, a_model_folds, self.bands, self.floor,
                   self.settings.gap_threshold_db)

    def heldout_spectra(self, Z):
        """Fold spectra of a model signal with each fold's gain fitted on the other fold."""
        return np.exp(swap(self.fold_gains(Z)))[:, None] * np.abs(Z)


def swap(v):
    """The two folds' values exchanged (held-out: each fold gets the other's)."""
    return v[::-1]


@dataclasses.dataclass(eq=False)
class State:
    """What the steps of a search change."""

    #: the candidates as given, and their context of specialisation (:class:`EffectContext`)
    originals: list
    ctx: EffectContext
    #: the candidates as specialised, the extended model about them, its current signal and
    #: parameters (fitting units; the effects added at their fitted values)
    candidates: list
    model: ExtendedModel
    m_sig: np.ndarray
    theta_units: np.ndarray
    steps: list[Step] = dataclasses.field(default_factory=list)
    #: one padded bin count for the candidates refit, never below an earlier step's
    n_bins: int = 0
    models: list = dataclasses.field(default_factory=list)
    residual_sets: list = dataclasses.field(default_factory=list)
    added: set[str] = dataclasses.field(default_factory=set)
    #: (f_x, step) of the located modulations added
    added_fx: list[tuple[float, int]] = dataclasses.field(default_factory=list)
    respecialised: list[int] = dataclasses.field(default_factory=list)


def open_search(record, spec, sample_rate, f_sun, settings: DiscoverySettings,
                say) -> Search:
    """The record cut to whole folds, its speed (given, tachometer, metadata or the record's
    lines; a record that holds no mesh line of this gearbox is refused at once), kinematics,
    DAQ and spectra."""
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    x, fs = as_signal(record, sample_rate)
    n = (len(x) // (2 * settings.n_folds)) * 2 * settings.n_folds
    x = x[:n] - np.mean(x[:n])

    kin0 = Kinematics.from_spec(spec)
    freqs_full, a_full = amplitude_spectrum(x, fs, "hann")
    op = resolve_speed(record if isinstance(record, Record)
                       else Record(x[None, :], fs, ("signal",), ("",)), spec, f_sun,
                       fallback=False)
    f_est = op.f_sun
    # the spec's speed unless the estimate moves the top of the band by more than half the
    # line tolerance (a calibrated spec carries its baseline's speed, which can differ from the
    # record's by more than that at the top of the band: benchmarks/README.md, "Moved from
    # module docstrings")
    rel = abs(f_est / kin0.f_sun - 1)
    df_full = float(freqs_full[1] - freqs_full[0])
    f_sun = (kin0.f_sun if op.method == "spectrum" and rel < 2e-4
             and rel * fs / 2 < 0.5 * settings.tolerance_bins * df_full else f_est)
    kin = Kinematics.from_spec(spec, f_sun)
    f_max = fs / 2
    say(f"speed {f_sun:.4f} Hz ({op.source}: {f_est:.4f}); fm {kin.f_mesh:.2f} Hz")

    # what the record measures: its channel's unit where it says (mm/s → velocity), else the spec's
    measured = unit_quantity(record.units[0]) if isinstance(record, Record) else None
    daq = daq_from_spec(spec, sample_rate=fs, snr_db=None,
                        quantity=measured or spec["sensor"]["quantity"])

    freqs, Yc = segment_spectra(x, fs, settings.n_folds)
    Y = np.abs(Yc)
    floor = noise_floor(Y, FLOOR_BINS)
    # the gap from the lowest knot of the calibrated response to the DAQ's pass band: the lines
    # outside are still found and labelled ("alias of 5fm", "fc"), not scored
    f_lo = lowest_knot(kin)
    bands = named_bands(kin, float(spec["sensor"]["passband"]) * fs, sample_rate=fs,
                        resolution=float(freqs[1] - freqs[0]), f_min=f_lo)
    tol_full = settings.tolerance_bins * (freqs_full[1] - freqs_full[0])
    chance = chance_match_probability(kin, tol_full, f_max, band_bounds(kin, f_max))
    return Search(spec, settings, say, x, fs, kin, f_sun, f_max, daq, freqs_full,
                  np.asarray(a_full), freqs, Y, floor, bands, f_lo, tol_full, chance,
                  list(spec["calibration"].get("shortfall_orders") or []),
                  normal_quantile(settings.confidence), chi2_quantile(settings.confidence))
