"""Calibration: fit what a real gearbox does not publish from healthy records of that machine.

A spec gives what a user knows (teeth, module, speed, load, where the sensor sits). The
vibration a housing accelerometer records also depends on what nobody publishes: the mesh
excitation (tooth micro-geometry, the loaded stiffness waveform), how the planets' mesh forces
reach the sensor (the planet-pass window's shape) and the structural path's frequency response.
:func:`calibrate` fits them from one or more healthy records and returns a **calibrated spec**
that every command accepts; the user's spec is never modified.

**What is fitted** (names as in the report and the calibrated spec):

- ``window_c1 … window_c{K-1}``: the planet-angle window's cosine coefficients
  (``sensor.window_harmonics``, :class:`dtwin.model.parts.transfer_path.PlanetPassTransferPath`);
  ``c_0`` is held at its initial value (the overall level belongs to the response below).
- ``excitation_ring_cos_h``, ``excitation_ring_sin_h`` (m): transmission-error harmonics of the
  ring-planet meshes for every mesh harmonic h below 0.45 × the sampling rate, at most
  :data:`dtwin.model.registry.N_EXCITATION_HARMONICS` (12, the spec's default stiffness waveform's;
  above them the twin's own waveform and the sensor response carry the lines)
  (:class:`dtwin.model.parts.mesh_excitation.MeshExcitation`). One housing sensor sees the sun
  meshes only through the same dynamics, so their excitation is not separately identifiable
  and is left at the spec's value.
- ``zeta_mesh``: the mesh damping ratio (fitted in log; a 5 kHz record far below the mesh
  modes usually leaves it not determined, and the report says so).
- ``frf_db_j`` (dB): the smooth sensor frequency response at log-spaced knots
  (:mod:`dtwin.simulation.sensor_response`), solved in closed form inside the residual function
  (variable projection): for given excitation and window the best knot gains are a linear
  least-squares problem in the log-amplitude, with a smoothness prior.
- ``load_share_1 … load_share_{N-1}``: each planet's load share relative to planet 0
  (``imperfections.load_sharing``; the twin gets the mesh clearances that give them,
  :func:`dtwin.model.parts.imperfections.load_share_offsets`). Fitted when the records show
  carrier-order lines ``k f_c`` with ``k`` not a multiple of ``N`` (`CalibrationSettings.load_sharing`):
  equally loaded, equally spaced planets seen through one planet-pass window make only
  ``k N f_c`` below the mesh band, so lines at the other orders say that the planets do not
  share the load equally (pin-hole position errors, a sun that cannot float far enough). A
  healthy machine's load sharing is its own and not published (ISO 6336-1's ``K_γ``).
- the measured noise floor (reported, not part of the twin).

**Held-out gap.** Each record is cut into two halves (:func:`dtwin.identify.gap.fold_segments`):
parameters fitted on the first halves are scored on the second and vice versa
(:func:`dtwin.identify.gap.gap`, per named band). The final parameters are fitted on all data,
written into the calibrated spec and **confirmed**: the calibrated twin is simulated again in
full (nonlinear, with its frequency response in the DAQ) and its gap to the records is
reported without any refit.

**Linearisation.** The response is first order in the excitation and the load shares, and
the window multiplies the mesh forces, so a fit that moves both departs from it. The
confirmation measures that: where the calibrated twin's confirmed gap exceeds the linearised
response's gap at the same values by more than `CalibrationSettings.converge_db`, or the
calibrated twin is no closer to the records than the spec as written (its confirmed gap not
below the "before" gap), the response is linearised again at the fitted values and the final
fit rerun from there (an outer Gauss–Newton iteration, at most
`CalibrationSettings.relinearize` times); the linearisation whose calibrated twin confirms
with the smallest gap is kept, and the cross-validation is repeated about its point (whose
start the whole records chose, so that held-out gap leans optimistic; the confirmed gap is the
one written into the spec). Where the twin still departs from the linearised response, it is
cross-validated itself, each half's values simulated in full. The response over one period of
the gear set is tiled only where the start-up transient has died out within the settling time
(the periodicity defect of the linearised simulation, as :func:`dtwin.simulation.simulate.simulate` checks
it): otherwise a longer settling time, then the whole record.

**Contact.** The fits keep every mesh's least deflection above zero, to first order
(:mod:`dtwin.identify.calibration_model`, "Contact"); the confirmation measures it on the twin
simulated in full (:func:`contact_margin`, written as ``[calibration] contact_margin``) and,
where the teeth part, linearises again at the fitted values; a linearisation whose twin keeps
its teeth in contact is preferred to one whose twin does not, whatever their gaps.

**Cross-validation.** The held-out gap fits the parameters on each half of each record and
scores the other half. Each half is fitted twice, from the linearisation point and from the fit
on all the records, and keeps the fit with the lower loss on its own half: the window and the
load shares multiply each other, and a fit from the linearisation point alone can stall at
several times its half's minimum loss, which would score the optimiser rather than the twin.
The second start carries information from the scored half, so where the halves' problems have
more than one minimum the held-out gap leans optimistic; the confirmed gap is the one written
into the spec. The other way round, the fit on all data can stop in a poorer minimum than its
halves found: where its gap on all the records exceeds the held-out gap by more than
:data:`STUCK_DB` (a fit scored on its own records cannot be worse than fits scored on records
they never saw, unless it stopped short), all data are fitted again from each half's values and
the fit of lowest loss is kept (on an independent three-planet gearbox, 19/38/95: a fit that
confirmed at 8.27 dB, held out 1.95 dB, refitted to 0.38 dB confirmed).

**Adoption** (:func:`adoption`). The calibrated values replace the spec's only when the held-out
gap, the confirmed gap and (where measured) the twin's own held-out gap all lie below the
spec as written's held-out gap with one fitted level; otherwise the calibrated spec keeps the
spec's values with that level, and says why.

The rooms: the settings (:mod:`dtwin.identify.calibration_settings`), the linearised model and
its fits (:mod:`dtwin.identify.calibration_model`), the result, its intervals, the calibrated
spec and the adoption rule (:mod:`dtwin.identify.calibration_result`); here the records, the
driver's stages and the held-out gap of a calibrated spec.

References: Golub & Pereyra (1973), "The differentiation of pseudo-inverses and nonlinear least
squares problems whose variables separate", SIAM J. Numer. Anal. 10(2); McFadden & Smith
(1985), "An explanation for the asymmetry of the modulation sidebands about the tooth meshing
frequency in epicyclic gear vibration", Proc. IMechE C 199(1).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from dtwin.errors import RecordError, SpecError
from dtwin.io.readers import read_record
from dtwin.io.record import Record
from dtwin.io.validate import MIN_CARRIER_PERIODS
from dtwin.signal.spectrum import noise_floor
from dtwin.signal.units import quantity as unit_quantity
from dtwin.simulation.sensor_response import knot_basis
from dtwin.simulation.simulate import SolverOptions, simulate
from dtwin.spec import Spec, load_spec
from dtwin.spec.build import build_twin, daq_from_spec

from .calibration_model import (
    _SHARE_UNIT,
    _TE_UNIT,
    CONTACT_SAMPLES,
    CONTACT_TOL,
    _carrier_order_lines,
    _Data,
    _family_bins,
    _fit,
    _model_amp,
    _prepare_twin,
    _response,
    mesh_harmonics,
    zeta_step,
)
from .calibration_result import (
    CalibratedParameter,
    CalibrationResult,
    _calibrated_data,
    _intervals,
    _kept_data,
    _spec_from_data,
    _Stamp,
    adoption,
)
from .calibration_settings import CalibrationSettings
from .gap import FLOOR_BINS, THRESHOLD_DB, GapResult, gap, named_bands, segment_spectra
from .lines import Kinematics
from .low_band import lowest_knot
from .operating_point import resolve_speed
from .shortfall import shortfall_lines

__all__ = ["CalibratedParameter", "CalibrationResult", "CalibrationSettings", "adoption",
           "calibrate", "heldout_gap", "mesh_harmonics"]


# ---------------------------------------------------------------------------------------- data
def _as_record(r: Record | str | os.PathLike) -> tuple[Record, str]:
    if isinstance(r, Record):
        return r, os.path.basename(str(r.metadata.get("source", "record")))
    return read_record(r), os.path.basename(os.fspath(r))


def _signal_rows(records: Sequence[Record], channel: int) -> tuple[np.ndarray, float]:
    rates = {float(r.sample_rate) for r in records}
    if len(rates) != 1:
        raise RecordError(f"calibration records need one sampling rate, got {sorted(rates)} Hz; "
                          "resample them or calibrate each rate separately")
    n = min(r.data.shape[-1] for r in records)
    rows = []
    for r in records:
        if channel >= r.data.shape[0]:
            raise RecordError(f"channel {channel} does not exist (the record has "
                              f"{r.data.shape[0]})")
        x = np.asarray(r.data[channel, :n], dtype=np.float64)
        if not np.all(np.isfinite(x)) or np.std(x) == 0:
            raise RecordError("a calibration record is constant or holds non-finite samples")
        rows.append(x - x.mean())
    return np.stack(rows), rates.pop()


def _records_unit(records: Sequence[Record], channel: int) -> str | None:
    """The unit of the records' `channel` (they must agree on what it measures)."""
    units = [r.units[channel] if channel < len(r.units) else "" for r in records]
    if len({unit_quantity(u) for u in units}) > 1:
        raise RecordError(f"calibration records measure different quantities ({sorted(set(units))});"
                          " calibrate on records of one quantity (acceleration, velocity or "
                          "displacement)")
    return units[0] or None


def _quantity(spec: Spec, unit: str | None = None) -> str:
    """What the records measure: their channel's unit where it says (``mm/s`` → velocity,
    `dtwin.signal.units.quantity`), else the spec's `sensor.quantity`."""
    q = unit_quantity(unit) or spec["sensor"]["quantity"]
    return "acceleration" if q == "ring_velocity" else q


def calibrate(
    records: Sequence[Record | str | os.PathLike],
    spec: Spec | str | os.PathLike,
    *,
    kind: str | None = None,
    channel: int = 0,
    settings: CalibrationSettings | None = None,
    progress: Callable[[str], None] | None = None,
    f_sun: float | None = None,
) -> CalibrationResult:
    """Calibrate the twin of `spec` on healthy `records` of the machine (module docstring).

    **Arguments:**

    - `records`: one or more healthy records (`Record` or paths), one sampling rate.
    - `spec`: the user's spec (`Spec` or a path); it is not modified.
    - `kind`: ``torsional`` / ``translational`` (default: the spec's ``model.kind``).
    - `channel`: the channel of each record to use.
    - `settings`: :class:`CalibrationSettings`.
    - `progress`: called with a line of text at each stage.
    - `f_sun`: the records' input speed (Hz), if known; otherwise each record's tachometer,
      metadata or lines give it (:func:`dtwin.identify.operating_point.resolve_speed`), and
      the mean is used.

    **Returns:** :class:`CalibrationResult` (the calibrated spec, parameters, gaps, spectra).

    **Raises:** `RecordError` for unusable records, `SpecError` for a spec the calibration
    cannot use, `FitError` when the twin cannot be simulated.
    """
    settings = settings or CalibrationSettings()
    say = progress or (lambda _m: None)
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    c = _Calibration.of(records, spec, kind, channel, settings, say, f_sun)
    gap_before = c.gap_before()
    tried, gap_held, held_fits = _final_fits(c, gap_before)
    # the confirmed gap decides, among the linearisations whose twin keeps its teeth in contact
    # where there is one (module docstring, "Contact")
    best = min(range(len(tried)), key=lambda i: (_teeth_part(tried[i].spec_data),
                                                  tried[i].gap.total))
    chosen = tried[best]
    if best > 0:
        say("cross-validation again, about the chosen linearisation point")
        gap_held, held_fits = c.cross_validated(chosen.lin, chosen.theta)
        say(f"held-out gap {gap_held.total:.2f} dB")
    params = _intervals(chosen.theta, chosen.gains, chosen.fit_data, c.layout, c.knots, c.Wl,
                        c.B, c.twin, c.i_exc, settings)
    data, gap_conf, a_after = chosen.spec_data, chosen.gap, chosen.amplitudes
    calibrated_conf = float(gap_conf.total)
    departs = bool(chosen.departure > settings.relinearize_db)
    held_full = None
    if departs and gap_held.total < gap_before.total and calibrated_conf < gap_before.total:
        # the held-out gap scores a response the twin does not follow: cross-validate the
        # twin itself, each half's values simulated in full and scored on the other half
        say("cross-validation of the twin simulated in full (it departs from the fitted "
            "response)")
        held_full = float(c.cross_validated_in_full(held_fits).total)
        say(f"held-out gap simulated in full {held_full:.2f} dB")
    why = adoption(gap_before.total, gap_held.total, calibrated_conf, held_full)
    if why:
        data, a_after, gap_conf = c.kept(why)
    c.record_in_spec(data, gap_conf, a_after)
    return CalibrationResult(data, params, c.f_sun, gap_before, gap_held, gap_conf, c.freqs,
                             c.a_meas, c.a_before, a_after, c.noise_rms, list(c.names),
                             chosen.steps, chosen.converged, best + 1, float(chosen.departure),
                             departs, bool(why), calibrated_conf, held_full)


#: The fit on all data is refitted from each half's values where its gap on those data exceeds
#: the held-out gap by more than this (dB): a fit scored on its own records cannot be worse than
#: fits scored on records they never saw, unless it stopped in a poorer minimum.
STUCK_DB = 1.0


def _final_fits(c: _Calibration, gap_before: GapResult
                ) -> tuple[list[_Attempt], GapResult, list]:
    """``(tried, gap_held, held_fits)``: the final fit on all data, confirmed by a full
    simulation, at the first linearisation point and, while the full simulation departs from
    the linearised response or is no closer to the records than the spec as written, at the
    fitted values again (`CalibrationSettings.relinearize`; module docstring,
    "Linearisation"); the cross-validation about the first point."""
    settings, say, lin = c.settings, c.say, c.lin0
    tried: list[_Attempt] = []  # one per linearisation point
    for attempt in range(settings.relinearize + 1):
        say("final fit on all data" if attempt == 0 else
            f"final fit on all data, linearised at the fitted values ({attempt} of "
            f"{settings.relinearize})")
        d_all = c.data_for(c.rec_idx, c.half_idx, lin)

        def fit_all(start, d_all=d_all):
            return _fit(d_all, start, settings.max_steps, settings.loss_rtol,
                        settings.run_steps, settings.restart_rtol)

        theta, steps, converged, loss = fit_all(lin[2])
        gap_lin = gap(c.freqs, c.a_meas, c.amp_at(theta, c.every, c.every, lin), c.bands)
        if attempt == 0:
            say("cross-validation: fitting on each half, scoring on the other")
            gap_held, held_fits = c.cross_validated(lin, theta)
            say(f"held-out gap {gap_before.total:.2f} dB before, {gap_held.total:.2f} dB "
                "calibrated")
            if gap_lin.total > gap_held.total + STUCK_DB:
                # worse on the records it was fitted to than the halves' fits on the records
                # they were not: the fit on all data stopped in a poorer minimum than its
                # halves found; it is fitted again from each half's values, the lowest loss kept
                say(f"the fit on all data ({gap_lin.total:.2f} dB) is worse than the held-out "
                    f"gap ({gap_held.total:.2f} dB): fitting all data again from each half's "
                    "values")
                for theta_h, _ in held_fits:
                    run = fit_all(theta_h)
                    if run[3] < loss:
                        theta, loss = run[0], run[3]
                        steps, converged = steps + run[1], run[2]
                gap_lin = gap(c.freqs, c.a_meas, c.amp_at(theta, c.every, c.every, lin),
                              c.bands)
        # the calibrated spec, then its confirmation by a full simulation
        _, G = _model_amp(jnp.asarray(theta), d_all)
        data = _calibrated_data(c.spec, theta, np.asarray(G), c.knots, c.layout, c.twin,
                                c.i_exc, c.stamp)
        say("confirming: the calibrated twin simulated in full")
        a_after, gap_conf = c.confirmed(data)
        tried.append(_Attempt(gap_conf, theta, lin, steps, converged, data, a_after,
                              gap_conf.total - gap_lin.total, d_all, np.asarray(G)))
        say(f"confirmed gap {gap_conf.total:.2f} dB; the linearised twin's "
            f"{gap_lin.total:.2f} dB ({steps} LM steps" + ("" if converged else
                                                          ", stopped at the step limit") + ")")
        # the response is first order in the excitation and the load shares (and bilinear in
        # them and the window): where the full simulation departs from it, linearise again at
        # the fitted values and refit from there (an outer Gauss–Newton iteration)
        departs = gap_conf.total > gap_lin.total + settings.converge_db
        i_zeta = c.layout.i_zeta
        if abs(float(theta[i_zeta] - lin[2][i_zeta])) > 0.99 * c.zeta_step:
            # the fit went as far in the damping as this linearisation is trusted with
            # (calibration_model's docstring, "Damping"): linearise there and go on
            say(f"the fit moved the mesh damping by a factor {math.exp(c.zeta_step):.2f}, as "
                "far as one linearisation follows it")
            departs = True
        if _teeth_part(data):
            # the full twin's teeth part where the linearised one's held: linearise there, so
            # that the contact rows see the parting (module docstring, "Contact")
            say(f"the calibrated twin's teeth part (least mesh deflection "
                f"{data['calibration']['contact_margin']:.2f} of its mean)")
            departs = True
        # (no closer than the spec as written: worth another linearisation only where the
        # cross-validation would adopt the values)
        if not departs and (gap_conf.total < gap_before.total
                            or not gap_held.total < gap_before.total):
            break
        if attempt < settings.relinearize:
            say((f"the full simulation departs from the linearised response by "
                 f"{gap_conf.total - gap_lin.total:.1f} dB" if departs else
                 f"the full simulation is no closer to the records than the spec as written "
                 f"({gap_conf.total:.2f} dB against {gap_before.total:.2f} dB)")
                + ": linearising again at the fitted values")
            lin = c.linearised(theta)
    return tried, gap_held, held_fits


@dataclasses.dataclass
class _Calibration:
    """One calibration's records, twin and linearised response (:func:`calibrate`'s state):
    the records' spectra (rows: record × half) and noise floor, the bins scored, the response
    knots and priors, the twin with its parameter layout, and the first linearisation."""

    spec: Spec
    kind: str | None
    settings: CalibrationSettings
    say: Callable[[str], None]
    names: tuple[str, ...]
    fs: float
    n: int
    quantity: str
    f_sun: float
    kin: Kinematics
    stamp: _Stamp
    freqs: np.ndarray
    A: np.ndarray
    F: np.ndarray
    twin: Any
    i_path: int
    i_exc: int
    layout: Any
    daq: Any
    band_top: float = 0.0
    lin0: Any = None
    noise_rms: float = 0.0
    S: np.ndarray | None = None
    Wl: np.ndarray | None = None
    knots: np.ndarray | None = None
    B: np.ndarray | None = None
    B1: np.ndarray | None = None
    prior: np.ndarray | None = None
    zeta_step: float = math.inf
    rec_idx: np.ndarray | None = None
    half_idx: np.ndarray | None = None
    every: np.ndarray | None = None
    bands: Any = None
    a_meas: np.ndarray | None = None
    a_before: np.ndarray | None = None

    @classmethod
    def of(cls, records, spec: Spec, kind, channel: int, settings: CalibrationSettings, say,
           f_sun: float | None) -> _Calibration:
        """The records read and checked, their speed and spectra, the twin prepared, its
        response linearised at the spec's values, and the bins and priors of the fits."""
        if not records:
            raise RecordError("calibration needs at least one healthy record")
        recs, names = zip(*(_as_record(r) for r in records), strict=True)
        X, fs = _signal_rows(recs, channel)
        unit = _records_unit(recs, channel)
        quantity, measured = _quantity(spec, unit), unit_quantity(unit)
        n_rec, n = X.shape
        f_sun, kin, how = _speed(spec, recs, X, fs, f_sun, channel)
        say(f"speed {f_sun:.4f} Hz from {n_rec} record(s) ({how})")
        stamp = _Stamp(f_sun, fs, measured, tuple(names), kind)  # what a calibrated spec records
        n_harm = mesh_harmonics(settings, fs, kin.f_mesh)
        # spectra of each half of each record
        freqs, Ymeas = segment_spectra(X, fs, 2)  # (rec, 2, bins)
        A = np.abs(Ymeas)
        F = noise_floor(A, FLOOR_BINS)
        n_orders = _carrier_order_lines(kin, freqs, A, F)
        fit_shares = settings.load_sharing == "on" or (settings.load_sharing == "auto"
                                                        and n_orders >= 2)
        if fit_shares:
            say(f"{n_orders} carrier orders k f_c (k not a multiple of {kin.n_planets}) above "
                "the line threshold: fitting the planets' load shares")
        twin, i_path, i_exc, layout = _prepare_twin(spec, f_sun, kind, settings, n_harm,
                                                    fit_shares)
        # the records' rate, not the spec's `sensor.sample_rate` (which describes other records)
        daq = daq_from_spec(spec, sample_rate=fs, snr_db=None, quantity=quantity, frf_hz=None,
                            frf_db=None)
        say(f"simulating the twin and its response to {layout.size} parameters "
            f"({n / fs:.1f} s at {fs:g} Hz)")
        c = cls(spec, kind, settings, say, names, fs, n, quantity, f_sun, kin, stamp, freqs, A,
                F, twin, i_path, i_exc, layout, daq)
        c.lin0 = c.linearised(jnp.zeros(layout.size))
        c._scored(n_rec, n_harm)
        return c

    def _scored(self, n_rec: int, n_harm: int) -> None:
        """The noise floor as an rms, the bins scored, the response knots, the priors, the
        rows (record × half) and the named bands."""
        settings, kin, freqs, A, F, fs = (self.settings, self.kin, self.freqs, self.A, self.F,
                                          self.fs)
        # the noise floor as an rms: a Hann amplitude spectrum of white noise of variance σ² has
        # Rayleigh amplitudes of median sqrt(2 ln 2 · 3 σ² / n_half)
        self.noise_rms = float(np.sqrt(np.median(F) ** 2 * (self.n // 2)
                                       / (6.0 * math.log(2.0))))
        fam = _family_bins(kin, freqs)
        strong = A > F * 10.0 ** (THRESHOLD_DB / 20.0)
        # the scored band ends where the DAQ's anti-aliasing pass band does (the spec's)
        self.band_top = band_top = float(self.spec["sensor"]["passband"]) * fs
        band = (freqs >= 0.5 * kin.f_carrier) & (freqs <= band_top)
        self.S = (fam[None, None, :] | strong) & band[None, None, :]
        self.Wl = strong & band[None, None, :]
        self.knots = np.geomspace(lowest_knot(kin), band_top, settings.n_knots)
        self.B = knot_basis(freqs, self.knots)
        layout = self.layout
        self.prior = np.concatenate([np.full(layout.n_window, settings.window_prior),
                                     np.full(2 * n_harm, settings.te_prior / _TE_UNIT),
                                     np.full(layout.n_share, settings.share_prior / _SHARE_UNIT),
                                     [settings.zeta_prior]])
        # how far one linearisation moves log ζ (calibration_model's docstring, "Damping")
        self.zeta_step = zeta_step(settings.relinearize_db)
        self.rec_idx = np.repeat(np.arange(n_rec), 2)
        self.half_idx = np.tile(np.arange(2), n_rec)
        self.every = np.ones(len(self.half_idx), bool)
        # the gap from the lowest knot up, as discovery's (dtwin.identify.gap, "The band")
        self.bands = named_bands(kin, band_top, sample_rate=fs,
                                 resolution=float(freqs[1] - freqs[0]), f_min=self.knots[0])
        self.a_meas = A.reshape(-1, A.shape[-1])
        # before: the spec's twin with its best response level (one gain), scored per half
        self.B1 = knot_basis(freqs, self.knots[:1])

    def linearised(self, theta_lin):
        """The model's halves (the same for every record) and their response at `theta_lin`."""
        # the meshes' least deflection over one carrier period (every relative position of
        # the planets), at most CONTACT_SAMPLES samples of it per mesh
        period = min(self.n, int(math.ceil(self.fs / self.kin.f_carrier)))
        idx = np.arange(0, period, max(1, int(math.ceil(period / CONTACT_SAMPLES))))
        y, J, contact = _response(self.twin, self.layout, self.i_path, self.i_exc, self.daq,
                                  self.n, self.f_sun, self.settings, theta_lin, idx)
        _, Z = segment_spectra(y, self.fs, 2)  # (2, bins)
        _, JZ = segment_spectra(J.T, self.fs, 2)  # (P, 2, bins)
        # JZ: (2, bins, P)
        return Z, np.moveaxis(JZ, 0, -1), np.asarray(theta_lin), contact

    def data_for(self, rows_rec, rows_half, lin):
        Z, JZ, theta_lin, contact = lin
        return _Data(
            Z0=jnp.asarray(Z[rows_half]), JZ=jnp.asarray(JZ[rows_half]),
            theta_lin=jnp.asarray(theta_lin),
            A=jnp.asarray(self.A[rows_rec, rows_half]), F=jnp.asarray(self.F[rows_rec, rows_half]),
            S=jnp.asarray(self.S[rows_rec, rows_half].astype(float)),
            W=jnp.asarray(self.Wl[rows_rec, rows_half].astype(float)), B=jnp.asarray(self.B),
            prior_sd=jnp.asarray(self.prior), smooth=self.settings.smooth_db,
            frf_prior=self.settings.frf_prior_db, **_contact_fields(contact),
            zeta_step=self.zeta_step,
        )

    def amp_at(self, theta, fit_rows, score_rows, lin):
        """The model's amplitudes at θ (response solved on `fit_rows`), on the rows
        `score_rows`."""
        rec_idx, half_idx = self.rec_idx, self.half_idx
        _, G = _model_amp(jnp.asarray(theta), self.data_for(rec_idx[fit_rows],
                                                             half_idx[fit_rows], lin))
        d = self.data_for(rec_idx[score_rows], half_idx[score_rows], lin)
        Z = d.Z0 + jnp.einsum("rbp,p->rb", d.JZ, jnp.asarray(theta - lin[2], d.JZ.dtype))
        return np.asarray(10.0 ** ((self.B @ np.asarray(G)) / 20.0))[None, :] * np.abs(np.asarray(Z))

    def gap_before(self) -> GapResult:
        """The held-out gap of the spec as written with its best response level (one gain),
        fitted on each half and scored on the other; keeps the amplitudes in `a_before`."""
        rec_idx, half_idx = self.rec_idx, self.half_idx
        self.a_before = np.empty_like(self.a_meas)
        for h in (0, 1):
            tr = half_idx == h
            d = self.data_for(rec_idx[tr], half_idx[tr], self.lin0)
            d = eqx.tree_at(lambda x: x.B, d, jnp.asarray(self.B1))
            _, G = _model_amp(jnp.zeros(self.layout.size), d)
            sc = half_idx == 1 - h
            self.a_before[half_idx != h] = float(10.0 ** (float(G[0]) / 20.0)) * np.abs(
                self.lin0[0][half_idx[sc]])
        return gap(self.freqs, self.a_meas, self.a_before, self.bands)

    def cross_validated(self, lin, warm):
        """The held-out gap about linearisation `lin` (fitted on each half, scored on the other
        with the linearised response) and the halves' fits, ``[(θ, data)]``. Each half is
        fitted from the linearisation point and from `warm` (the fit on all the records), and
        keeps the fit with the lower loss on its own half: a half's fit from the linearisation
        point alone can stall far above its minimum (the window and the load shares multiply
        each other), which would score the optimiser, not the model."""
        settings, rec_idx, half_idx = self.settings, self.rec_idx, self.half_idx
        a_held = np.empty_like(self.a_meas)
        fits = []
        for h in (0, 1):
            tr = half_idx == h
            d = self.data_for(rec_idx[tr], half_idx[tr], lin)
            # each run's own final loss on this half (the fit computes it) picks the start
            theta_h = min((_fit(d, start, settings.max_steps, settings.loss_rtol,
                                settings.run_steps, settings.restart_rtol)
                           for start in (lin[2], warm)), key=lambda run: run[3])[0]
            a_held[half_idx != h] = self.amp_at(theta_h, tr, half_idx != h, lin)
            fits.append((theta_h, d))
        return gap(self.freqs, self.a_meas, a_held, self.bands), fits

    def cross_validated_in_full(self, fits):
        """The held-out gap of the halves' fits `fits` (:meth:`cross_validated`), each half's
        values simulated in full and scored on the other half."""
        half_idx = self.half_idx
        a_held = np.empty_like(self.a_meas)
        for h, (theta_h, d) in enumerate(fits):
            _, G = _model_amp(jnp.asarray(theta_h), d)
            a = self.confirmed(_calibrated_data(self.spec, theta_h, np.asarray(G), self.knots,
                                                self.layout, self.twin, self.i_exc,
                                                self.stamp))[0]
            a_held[half_idx != h] = a[half_idx != h]
        return gap(self.freqs, self.a_meas, a_held, self.bands)

    def confirmed(self, data):
        """Amplitudes (rows: record × half) and gap of the twin of spec `data` simulated in
        full over the records, nothing refitted."""
        n, fs, f_sun = self.n, self.fs, self.f_sun
        cal_spec = _spec_from_data(data)
        res = simulate(
            build_twin(cal_spec, kind=self.kind, f_sun=f_sun), duration=n / fs, f_sun=f_sun,
            daq=daq_from_spec(cal_spec, sample_rate=fs, snr_db=None, quantity=self.quantity),
            discard=self.settings.discard, solver=self.settings.solver)
        margin = contact_margin(res)
        if math.isfinite(margin):
            data["calibration"]["contact_margin"] = round(margin, 4)
        y = np.asarray(res.signal[:n])
        a = np.abs(segment_spectra(y, fs, 2)[1])[self.half_idx]
        return a, gap(self.freqs, self.a_meas, a, self.bands)

    def kept(self, why: str):
        """``(data, amplitudes, gap)`` of the spec as written, kept: the calibrated values fit
        the training half in directions the records do not determine and generalise worse than
        the spec as written, or the twin simulated in full does not bear them out
        (:func:`adoption`): the spec, with the level the "before" model fitted, on all the
        data."""
        self.say(f"the calibrated values are not adopted ({why}): keeping the spec's values, "
                 "with its fitted response level")
        d_flat = eqx.tree_at(lambda x: x.B, self.data_for(self.rec_idx, self.half_idx, self.lin0),
                             jnp.asarray(self.B1))
        _, G1 = _model_amp(jnp.zeros(self.layout.size), d_flat)
        data = _kept_data(self.spec, float(G1[0]), self.knots, self.stamp, why)
        a_after, gap_conf = self.confirmed(data)
        self.say(f"confirmed gap of the spec as written {gap_conf.total:.2f} dB")
        return data, a_after, gap_conf

    def record_in_spec(self, data, gap_conf: GapResult, a_after) -> None:
        """The confirmed gap and what the calibrated twin still leaves unexplained on the
        healthy records (discovery refuses a candidate whose evidence lies there,
        :mod:`dtwin.identify.shortfall`), written into `data`'s ``[calibration]``."""
        data["calibration"]["heldout_gap_db"] = round(float(gap_conf.total), 3)
        orders, excess = shortfall_lines(self.freqs, self.a_meas, a_after, self.kin,
                                         self.band_top)
        data["calibration"]["shortfall_orders"] = [round(o, 6) for o in orders]
        data["calibration"]["shortfall_db"] = [round(e, 2) for e in excess]


def _teeth_part(data) -> bool:
    """Whether the twin of calibrated spec `data`, simulated in full, parts its teeth
    (``[calibration] contact_margin`` below 0, :func:`contact_margin`)."""
    return data["calibration"].get("contact_margin", 1.0) < 0


def _contact_fields(contact) -> dict:
    """`_Data`'s contact rows (:func:`~dtwin.identify.calibration_model._contact_rows`) from a
    linearisation's :class:`~dtwin.identify.calibration_model._Contact` (none without one)."""
    if contact is None:
        return {}
    return dict(contact_d0=jnp.asarray(contact.d0), contact_J=jnp.asarray(contact.J),
                contact_scale=CONTACT_TOL * contact.mean)


def contact_margin(res) -> float:
    """The least mesh deflection of a simulation (`SimResult`), over the planets, the record
    and both meshes, each mesh's over its mean deflection (1): below 0 the teeth of some mesh
    part (module docstring, "Contact")."""
    out = res.outputs
    m = []
    for mesh in ("sun_planet", "ring_planet"):
        mean = float(np.mean(np.asarray(out[f"deflection_{mesh}"])))
        if mean > 0:
            m.append(float(np.min(np.asarray(out[f"least_deflection_{mesh}"]))) / mean)
    return min(m) if m else float("nan")


def _speed(spec: Spec, recs, X, fs: float, f_sun: float | None, channel: int):
    """``(f_sun, kinematics, how)``: the records' speed, given or each record's (tachometer,
    metadata, lines) averaged over the records, after the spec's nominal speed and the records'
    length are checked; a record that holds no mesh line of this gearbox cannot calibrate it:
    refused at once."""
    n = X.shape[1]
    g = spec["gears"]
    if spec["operating"]["f_sun"] is None:
        raise SpecError([("operating.f_sun", "calibration needs the nominal input speed (Hz)")])
    kin0 = Kinematics.from_spec(spec)
    if n / fs < MIN_CARRIER_PERIODS / kin0.f_carrier * (1.0 - 1e-9):
        raise RecordError(f"{n / fs:.3g} s is shorter than {MIN_CARRIER_PERIODS:g} carrier "
                          f"periods ({MIN_CARRIER_PERIODS / kin0.f_carrier:.3g} s): the "
                          "sidebands at f_c cannot be resolved in each half; calibrate on "
                          "longer records")
    ops = [resolve_speed(r, spec, f_sun, channel=channel, fallback=False) for r in recs]
    f_sun = float(np.mean([op.f_sun for op in ops]))
    kin = Kinematics.from_gears(g["z_sun"], g["z_planet"], g["z_ring"], g["n_planets"], f_sun)
    return f_sun, kin, ops[0].source




class _Attempt(NamedTuple):
    """One final fit of :func:`calibrate`, at one linearisation point: its confirmed gap, θ,
    the linearisation, LM steps, convergence, the calibrated spec's data, the confirmed
    amplitudes, the confirmed gap's departure from the linearised one (dB), the fit's data
    and its response gains."""

    gap: GapResult
    theta: np.ndarray
    lin: Any
    steps: int
    converged: bool
    spec_data: dict
    amplitudes: np.ndarray
    departure: float
    fit_data: _Data
    gains: np.ndarray


def heldout_gap(
    spec: Spec | str | os.PathLike,
    records: Sequence[Record | str | os.PathLike],
    *,
    kind: str | None = None,
    channel: int = 0,
    discard: float = 0.3,
    solver: SolverOptions | None = None,
) -> GapResult:
    """The gap (dB, per named band) between records the calibration did not see and the twin of
    a (calibrated) `spec`, simulated at each record's own speed with no refit of anything.

    Rows are the records' halves, as in :func:`calibrate`; the band ends at the spec's
    ``[sensor] passband`` × the rate. **Arguments:** `spec` (`Spec` or path), `records` (`Record` or paths, one rate),
    `kind`, `channel`, `discard` (s), `solver`.
    """
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    recs, _ = zip(*(_as_record(r) for r in records), strict=True)
    X, fs = _signal_rows(recs, channel)
    unit = _records_unit(recs, channel)
    n = X.shape[1]
    kin0 = Kinematics.from_spec(spec)
    g = spec["gears"]
    daq = daq_from_spec(spec, sample_rate=fs, snr_db=None, quantity=_quantity(spec, unit))
    a_meas, a_model, kin = [], [], kin0
    for rec, x in zip(recs, X, strict=True):
        f_sun = resolve_speed(rec, spec, channel=channel).f_sun
        kin = Kinematics.from_gears(g["z_sun"], g["z_planet"], g["z_ring"], g["n_planets"],
                                    f_sun)
        tw = build_twin(spec, kind=kind, f_sun=f_sun)
        y = np.asarray(simulate(tw, duration=n / fs, f_sun=f_sun, daq=daq, discard=discard,
                                solver=solver).signal[:n])
        freqs, Y = segment_spectra(x, fs, 2)
        _, Z = segment_spectra(y, fs, 2)
        a_meas.append(np.abs(Y))
        a_model.append(np.abs(Z))
    return gap(freqs, np.concatenate(a_meas), np.concatenate(a_model),
               named_bands(kin, float(spec["sensor"]["passband"]) * fs, sample_rate=fs,
                           resolution=float(freqs[1] - freqs[0]),
                           f_min=lowest_knot(kin)))
