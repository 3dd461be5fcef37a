"""Calibration: fit what a real gearbox does not publish from healthy records of that machine.

A spec gives what a user knows (teeth, module, speed, load, where the sensor sits). The
vibration a housing accelerometer records also depends on what nobody publishes: the mesh
excitation (tooth micro-geometry, the loaded stiffness waveform), how the planets' mesh forces
reach the sensor (the planet-pass window's shape) and the structural path's frequency response.
:func:`calibrate` fits them from one or more healthy records and returns a **calibrated spec**
that every command accepts; the user's spec is never modified.

**What is fitted** (names as in the report and the calibrated spec):

- ``window_c1 … window_c{K-1}``: the planet-angle window's cosine coefficients
  (``sensor.window_harmonics``, :class:`dtwin.parts.transfer_path.PlanetPassTransferPath`);
  ``c_0`` is held at its initial value (the overall level belongs to the response below).
- ``excitation_ring_cos_h``, ``excitation_ring_sin_h`` (m): transmission-error harmonics of the
  ring-planet meshes for every mesh harmonic h below 0.45 × the sampling rate, at most
  :data:`dtwin.registry.N_EXCITATION_HARMONICS` (12, the spec's default stiffness waveform's;
  above them the twin's own waveform and the sensor response carry the lines)
  (:class:`dtwin.parts.mesh_excitation.MeshExcitation`). One housing sensor sees the sun
  meshes only through the same dynamics, so their excitation is not separately identifiable
  and is left at the spec's value.
- ``zeta_mesh``: the mesh damping ratio (fitted in log; a 5 kHz record far below the mesh
  modes usually leaves it not determined, and the report says so).
- ``frf_db_j`` (dB): the smooth sensor frequency response at log-spaced knots
  (:mod:`dtwin.sensor_response`), solved in closed form inside the residual function
  (variable projection): for given excitation and window the best knot gains are a linear
  least-squares problem in the log-amplitude, with a smoothness prior.
- ``load_share_1 … load_share_{N-1}``: each planet's load share relative to planet 0
  (``imperfections.load_sharing``; the twin gets the mesh clearances that give them,
  :func:`dtwin.parts.imperfections.load_share_offsets`). Fitted when the records show
  carrier-order lines ``k f_c`` with ``k`` not a multiple of ``N`` (`CalibrationSettings.load_sharing`):
  equally loaded, equally spaced planets seen through one planet-pass window make only
  ``k N f_c`` below the mesh band, so lines at the other orders say that the planets do not
  share the load equally (pin-hole position errors, a sun that cannot float far enough). A
  healthy machine's load sharing is its own and not published (ISO 6336-1's ``K_γ``).
- the measured noise floor (reported, not part of the twin).

**Model.** The twin is simulated once at the record's speed (estimated from its spectrum) and
the sensor signal's first-order response to the fitted parameters is computed with forward-mode
derivatives through the diffrax solve (``jax.jacfwd``). The window coefficients enter after
the ODE and the transmission error linearly, so ``y(θ) = y_0 + J θ`` is exact in the former and
first-order in the latter two. Complex Hann spectra of each record segment then give
``A(θ) = |H(f)| |Z_0 + J_Z θ|``, compared with the measured ``A_meas`` as levels
``20 log10(A + F)`` (``F`` the measured noise floor; model side with its expected noise,
``sqrt(A² + F²)``, as :mod:`dtwin.identify.residuals`) over the bins of the gearbox's line
families (``k f_c`` below the first mesh band, ``m f_m + n f_c`` with ``|n| ≤ 10``) and of every
measured line. Gaussian priors keep undetermined parameters at their initial values.

**Held-out gap.** Each record is cut into two halves (:func:`dtwin.identify.gap.fold_segments`):
parameters fitted on the first halves are scored on the second and vice versa
(:func:`dtwin.identify.gap.gap`, per named band). The final parameters are fitted on all data,
written into the calibrated spec and **confirmed**: the calibrated twin is simulated again in
full (nonlinear, with its frequency response in the DAQ) and its gap to the records is
reported without any refit.

**Linearisation.** The response is first order in the excitation and the load shares, and
the window multiplies the mesh forces, so a fit that moves both departs from it. The
confirmation measures that: where the calibrated twin's confirmed gap exceeds the linearised
response's gap at the same values by more than `CalibrationSettings.relinearize_db`, or the
calibrated twin is no closer to the records than the spec as written (its confirmed gap not
below the "before" gap), the response is linearised again at the fitted values and the final
fit rerun from there (an outer Gauss–Newton iteration, at most
`CalibrationSettings.relinearize` times); the linearisation whose calibrated twin confirms
with the smallest gap is kept, and the cross-validation is repeated about its point (whose
start the whole records chose, so that held-out gap leans optimistic; the confirmed gap is the
one written into the spec). Where the twin still departs from the linearised response, it is
cross-validated itself, each half's values simulated in full. The response over one period of
the gear set is tiled only where the start-up transient has died out within the settling time
(the periodicity defect of the linearised simulation, as :func:`dtwin.simulate.simulate` checks
it): otherwise a longer settling time, then the whole record.

**Cross-validation.** The held-out gap fits the parameters on each half of each record and
scores the other half. Each half is fitted twice, from the linearisation point and from the fit
on all the records, and keeps the fit with the lower loss on its own half: the window and the
load shares multiply each other, and a fit from the linearisation point alone can stall at
several times its half's minimum loss, which would score the optimiser rather than the twin.
The second start carries information from the scored half, so where the halves' problems have
more than one minimum the held-out gap leans optimistic; the confirmed gap is the one written
into the spec.

**Adoption** (:func:`adoption`). The calibrated values replace the spec's only when the held-out
gap, the confirmed gap and (where measured) the twin's own held-out gap all lie below the
spec as written's held-out gap with one fitted level; otherwise the calibrated spec keeps the
spec's values with that level, and says why.

**Intervals.** Gauss–Newton at the optimum, with the residual variance estimated from the
residuals themselves (so lack of fit widens every interval). A parameter is *determined* when
the data shrink its prior standard deviation by at least half; *determined jointly* with others
when they do so only with the others held (its conditional standard deviation, ``1/sqrt`` of
its diagonal of the information, below half the prior's, its marginal one not), and the report
names those it trades with, by posterior correlation (a transmission-error harmonic's cosine
and sine: an amplitude spectrum fixes their amplitude, not their phase); *not determined*
otherwise. A knot of the response is determined when a measured line lies within its support
and its standard deviation is below 3 dB.

**The fits.** Levenberg–Marquardt in coordinates where every Jacobian column has unit norm,
run in short runs (`CalibrationSettings.run_steps`), each started where the last one ended
with column scales taken there, until a run no longer lowers the loss: one long run from
θ = 0 can crawl on a shallow slope far above the minimum.

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
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from dtwin._version import __version__
from dtwin.build import build_twin, daq_from_spec
from dtwin.errors import FitError, RecordError, SpecError
from dtwin.io.readers import read_record
from dtwin.io.record import Record
from dtwin.io.validate import MIN_CARRIER_PERIODS
from dtwin.lumped import replace as replace_lumped
from dtwin.parts.imperfections import MeshOffsets, load_share_offsets
from dtwin.parts.mesh_excitation import MeshExcitation
from dtwin.parts.transfer_path import PlanetPassTransferPath, window_cosine_coefficients
from dtwin.registry import N_EXCITATION_HARMONICS, N_WINDOW_TERMS
from dtwin.sensor_response import knot_basis
from dtwin.simulate import SolverOptions, settling_sequence, simulate
from dtwin.spec import Spec, load_spec, spec_to_dict
from dtwin.spec_writer import spec_to_toml
from dtwin.spectrum import noise_floor
from dtwin.units import quantity as unit_quantity

from .gap import FLOOR_BINS, THRESHOLD_DB, GapResult, gap, named_bands, segment_spectra
from .lines import Kinematics
from .operating_point import resolve_speed
from .shortfall import shortfall_lines
from .stopping import StallStopping

__all__ = ["CalibratedParameter", "CalibrationResult", "CalibrationSettings", "adoption",
           "calibrate", "heldout_gap", "mesh_harmonics"]

_DB = 20.0 / math.log(10.0)
#: Unit (m) of the transmission-error coordinates in θ.
_TE_UNIT = 1e-8
#: Unit of the load-share coordinates in θ (1 % of planet 0's share).
_SHARE_UNIT = 0.01
#: Memory (bytes) the response's tangents may take at once, and what one tangent takes per
#: sample of the DAQ's oversampled grid (measured: 1.0–1.4 kB on the paper's gearbox, the
#: torsional twin): the Jacobian is formed in batches of tangents within this budget.
_TANGENT_BUDGET, _TANGENT_BYTES_PER_SAMPLE = 2**30, 1500


@dataclasses.dataclass(frozen=True)
class CalibrationSettings:
    """Settings of :func:`calibrate` (all optional).

    - `window_terms`: K, cosine terms of the window (``c_0 … c_{K-1}``).
    - `n_knots`: knots of the sensor frequency response, log-spaced from 0.8 N f_c to the top
      of the pass band (the spec's ``[sensor] passband`` × the rate).
    - `mesh_harmonics`: mesh harmonics with a fitted excitation, at most
      :data:`dtwin.registry.N_EXCITATION_HARMONICS` (None: all below 0.45 × rate, up to that).
    - `discard` (s): start-up simulated before the record (the path's filter settles).
    - `te_prior` (m): prior standard deviation of each transmission-error coefficient.
    - `window_prior`: prior standard deviation of each window coefficient, relative to ``c_0``.
    - `zeta_prior`: prior standard deviation of ``log zeta_mesh`` (small: the response is
      linearised in it).
    - `smooth_db`: prior standard deviation (dB) of the response's second difference per knot.
    - `frf_prior_db`: prior standard deviation (dB) of a knot about the mean level.
    - `max_steps`: Levenberg–Marquardt steps per fit at most, all its runs together.
    - `run_steps`, `restart_rtol`: a fit is a sequence of Levenberg–Marquardt runs of at most
      `run_steps` steps, each from where the last one ended with fresh column scales and trust
      region (a run from θ = 0 can crawl on a shallow slope), until a run lowers the loss by
      no more than `restart_rtol` of itself.
    - `loss_rtol`: a run stops earlier when an accepted step lowers its loss by less than
      `loss_rtol` of itself (:class:`dtwin.identify.stopping.StallStopping`): the window and
      excitation terms the records do not determine otherwise keep moving by ever smaller
      decreases of the loss.
    - `load_sharing`: fit the planets' load shares ``"on"``, ``"off"``, or ``"auto"``
      (default): when at least two orders ``k f_c`` below the first mesh band, ``k`` not a
      multiple of N, stand above the line threshold in the records (module docstring).
    - `share_prior`: prior standard deviation of each relative load share.
    - `solver`: `dtwin.simulate.SolverOptions` of the simulations. None: the linearised
      response is one period of the gear set after a settling time, tiled
      (``SolverOptions(periodic="auto")``, which integrates the whole record when the twin is
      not periodic at constant speed), and the confirmation integrates the whole record.
    - `relinearize`, `relinearize_db`: when the confirmation's gap exceeds the linearised
      response's gap at the fitted values by more than `relinearize_db` (dB), or is not below
      the spec as written's held-out gap, the response is linearised again there and the
      final fit rerun from there, at most `relinearize` times;
      the linearisation whose calibrated twin confirms with the smallest gap is kept (module
      docstring, "Linearisation").
    """

    window_terms: int = 7
    n_knots: int = 5
    mesh_harmonics: int | None = None
    discard: float = 0.3
    te_prior: float = 2e-6
    window_prior: float = 1.0
    zeta_prior: float = 0.3
    smooth_db: float = 1.0
    frf_prior_db: float = 60.0
    max_steps: int = 400
    loss_rtol: float = 1e-8
    run_steps: int = 50
    restart_rtol: float = 1e-5
    solver: SolverOptions | None = None
    load_sharing: str = "auto"
    share_prior: float = 0.3
    relinearize: int = 2
    relinearize_db: float = 1.0

    def __post_init__(self):
        if self.load_sharing not in ("auto", "on", "off"):
            raise SpecError([("load_sharing", "must be 'auto', 'on' or 'off', got "
                              f"{self.load_sharing!r}")])
        if self.window_terms < 2:
            raise SpecError([("window_terms", "needs at least 2 cosine terms")])
        if self.window_terms > N_WINDOW_TERMS:
            raise SpecError([("window_terms", f"at most {N_WINDOW_TERMS} cosine terms (those "
                              f"with a registry name), got {self.window_terms}")])
        if self.mesh_harmonics is not None and not (
                1 <= self.mesh_harmonics <= N_EXCITATION_HARMONICS):
            raise SpecError([("mesh_harmonics", f"must be 1 … {N_EXCITATION_HARMONICS} (the "
                              f"excitation harmonics with a registry name), got "
                              f"{self.mesh_harmonics}")])
        if self.n_knots < 1:
            raise SpecError([("n_knots", "needs at least one knot")])
        for name in ("te_prior", "window_prior", "zeta_prior", "smooth_db", "frf_prior_db",
                     "share_prior"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise SpecError([(name, f"must be a positive number, got {v!r}")])
        if not (math.isfinite(self.loss_rtol) and self.loss_rtol >= 0):
            raise SpecError([("loss_rtol", f"must be a number >= 0, got {self.loss_rtol!r}")])
        if self.run_steps < 1 or not (math.isfinite(self.restart_rtol) and self.restart_rtol >= 0):
            raise SpecError([("run_steps/restart_rtol", "run_steps must be >= 1 and "
                              f"restart_rtol a number >= 0, got {self.run_steps!r}, "
                              f"{self.restart_rtol!r}")])
        if self.relinearize < 0 or not (math.isfinite(self.relinearize_db)
                                        and self.relinearize_db >= 0):
            raise SpecError([("relinearize/relinearize_db", "relinearize must be >= 0 and "
                              f"relinearize_db a number >= 0 dB, got {self.relinearize!r}, "
                              f"{self.relinearize_db!r}")])
        if self.discard < 0 or self.max_steps < 1:
            raise SpecError([("discard/max_steps", "discard must be >= 0 s and max_steps >= 1")])


@dataclasses.dataclass(frozen=True)
class CalibratedParameter:
    """One calibrated quantity: value, unit, standard deviation and whether the data determine
    it (module docstring), with a short note."""

    name: str
    value: float
    unit: str
    sd: float
    prior_sd: float
    determined: bool
    note: str = ""
    #: when not `determined` alone but the data determine it with the others held (its
    #: conditional standard deviation below half the prior's): the parameters it trades with,
    #: as ``(name, correlation)``, the strongest first
    joint_with: tuple[tuple[str, float], ...] = ()

    @property
    def status(self) -> str:
        """``determined``, ``determined jointly with …`` or ``not determined``."""
        if self.determined:
            return "determined"
        if self.joint_with:
            return "determined jointly with " + ", ".join(
                f"{n} (correlation {r:+.2f})" for n, r in self.joint_with)
        return "not determined"

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "status": self.status}


@dataclasses.dataclass
class CalibrationResult:
    """What :func:`calibrate` found.

    - `spec_data`: the calibrated spec as a mapping (write it with :meth:`write_spec`).
    - `parameters`: every calibrated quantity (:class:`CalibratedParameter`).
    - `f_sun` (Hz): the speed estimated from the records.
    - `gap_before`: held-out gap of the uncalibrated twin (a fitted gain only), dB per band.
    - `gap_heldout`: cross-validated gap of the calibrated model (fit on one half, scored on
      the other), dB per band.
    - `gap_confirmed`: gap of the calibrated twin simulated in full, no refit, dB per band.
    - `freqs` (Hz), `a_meas`, `a_before`, `a_after`: amplitude spectra (rows: record × half)
      of the records, the uncalibrated and the confirmed calibrated twin, in the record's unit.
    - `noise_rms`: the measured noise floor as an rms (record unit).
    - `records`: names of the records.
    - `fit_steps`: Levenberg–Marquardt steps of the final fit; `fit_converged`: False when it
      stopped at `CalibrationSettings.max_steps` with its loss still falling.
    - `linearisations`: the linearisation the calibrated values come from (1: the response
      at the spec's values; more when the full simulation departed from it and the fit was
      linearised again at its values, `CalibrationSettings.relinearize`).
    - `departure_db`: the confirmed gap minus the linearised response's gap at the calibrated
      values (dB, all data); `departs`: whether it stayed above
      `CalibrationSettings.relinearize_db` (the calibrated values lie where the response is
      not first order, and the held-out gap, which scores the linearised response, is
      optimistic: read the confirmed one).
    - `calibrated_confirmed_db`: the confirmed gap of the calibrated values (dB, all data),
      whether adopted or not; `heldout_full_db`: where the calibrated twin departs from the
      linearised response, its held-out gap simulated in full (dB; None when not measured).
    - `kept_spec`: the calibrated values did not bring the twin closer to the records than the
      spec as written (not `improves`), so `spec_data` keeps the spec's own values with only
      the response level fitted (one flat gain), as the "before" model; `parameters` and
      `gap_heldout` still describe the calibration that was not adopted, `gap_confirmed` and
      `a_after` the spec that was kept, simulated in full.
    """

    spec_data: dict[str, Any]
    parameters: list[CalibratedParameter]
    f_sun: float
    gap_before: GapResult
    gap_heldout: GapResult
    gap_confirmed: GapResult
    freqs: np.ndarray
    a_meas: np.ndarray
    a_before: np.ndarray
    a_after: np.ndarray
    noise_rms: float
    records: list[str]
    fit_steps: int = 0
    fit_converged: bool = True
    linearisations: int = 1
    departure_db: float = 0.0
    departs: bool = False
    kept_spec: bool = False
    calibrated_confirmed_db: float | None = None
    heldout_full_db: float | None = None

    @property
    def improves(self) -> bool:
        """Whether the calibrated values are adopted: the calibrated twin is closer to the
        records than the spec as written (:func:`adoption`, which says why not). When it is
        not, the healthy records hold something the calibrated parameters cannot represent (an
        effect for discovery), or the calibrated values lie where the twin is not first order
        in them, and the calibrated spec should not replace the user's."""
        return not self.rejection

    @property
    def rejection(self) -> str:
        """Why the calibrated values were not adopted ("" when they were: :func:`adoption`)."""
        return adoption(self.gap_before.total, self.gap_heldout.total,
                        self.calibrated_confirmed_db, self.heldout_full_db)

    @property
    def not_determined(self) -> list[str]:
        """Parameters the records determine neither alone nor jointly with the others."""
        return [p.name for p in self.parameters if not (p.determined or p.joint_with)]

    @property
    def jointly_determined(self) -> list[str]:
        """Parameters the records determine only jointly with others (their `joint_with`)."""
        return [p.name for p in self.parameters if not p.determined and p.joint_with]

    def spec(self) -> Spec:
        """The calibrated spec, validated."""
        return _spec_from_data(self.spec_data)

    def write_spec(self, path: str | os.PathLike) -> None:
        """Write the calibrated spec as TOML at `path` (a new file)."""
        with open(path, "x", encoding="utf-8") as f:
            f.write(spec_to_toml(self.spec_data, header=_HEADER))

    def table(self) -> str:
        rows = [f"speed {self.f_sun:.4f} Hz (from the records); noise floor rms "
                f"{self.noise_rms:.3g}",
                f"gap (dB): before {self.gap_before.total:.2f}, held-out "
                f"{self.gap_heldout.total:.2f}, confirmed {self.gap_confirmed.total:.2f}"
                + ("" if self.improves else f" (NOT adopted: {self.rejection}"
                   + ("; the spec's values kept, with its fitted level)" if self.kept_spec
                      else ")")),
                f"final fit: {self.fit_status}",
                f"{'parameter':<24} {'value':>12} {'sd':>10} {'unit':<6} status"]
        for p in self.parameters:
            status = p.status
            if p.note:
                status += f" ({p.note})"
            # six significant figures: a frequency knot of 2494.8 Hz is not 2495
            rows.append(f"{p.name:<24} {p.value:>12.6g} {p.sd:>10.2g} {p.unit:<6} {status}")
        return "\n".join(rows)

    @property
    def fit_status(self) -> str:
        """The final fit's stop, in words."""
        about = ("" if self.linearisations == 1 else
                 f", linearised at the fitted values (linearisation {self.linearisations})")
        if self.fit_converged:
            return f"converged in {self.fit_steps} Levenberg–Marquardt steps{about}"
        return (f"stopped at the step limit ({self.fit_steps} Levenberg–Marquardt steps) with "
                f"its loss still falling: raise CalibrationSettings.max_steps{about}")

    def to_dict(self) -> dict[str, Any]:
        return dict(
            f_sun=self.f_sun, records=self.records, noise_rms=self.noise_rms,
            fit_steps=self.fit_steps, fit_converged=self.fit_converged,
            linearisations=self.linearisations, departure_db=self.departure_db,
            departs=self.departs,
            gap_before=self.gap_before.to_dict(), gap_heldout=self.gap_heldout.to_dict(),
            gap_confirmed=self.gap_confirmed.to_dict(),
            parameters=[p.to_dict() for p in self.parameters],
            not_determined=self.not_determined, jointly_determined=self.jointly_determined,
            improves=self.improves, kept_spec=self.kept_spec,
            calibrated_confirmed_db=self.calibrated_confirmed_db,
            heldout_full_db=self.heldout_full_db, rejection=self.rejection,
        )


_HEADER = ("Calibrated by dtwin calibrate: fitted from healthy records (see [calibration]).\n"
           "The user's spec is unchanged; this file adds the fitted window shape, mesh\n"
           "excitation, mesh damping and sensor frequency response.")


def _spec_from_data(data: dict[str, Any]) -> Spec:
    import tempfile

    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False, encoding="utf-8") as f:
        f.write(spec_to_toml(data))
        path = f.name
    try:
        return load_spec(path)
    finally:
        os.unlink(path)


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


# ------------------------------------------------------------------------------------ the model
@dataclasses.dataclass(frozen=True)
class _Layout:
    """Positions of the parameter groups in θ and their scales (θ is nondimensional)."""

    n_window: int  # free window coefficients c_1 … c_{K-1}
    n_harm: int  # mesh harmonics of the excitation
    c_init: tuple[float, ...]
    window_scale: float
    te_scale: float
    n_share: int = 0  # free load shares of planets 1 … N-1 (0: not fitted)
    share_init: tuple[float, ...] = ()
    f_sun: float = 0.0  # Hz, the speed at which the shares hold
    i_share_part: int = -1  # the MeshOffsets part that carries them

    @property
    def size(self) -> int:
        return self.n_window + 2 * self.n_harm + self.n_share + 1

    @property
    def i_share(self) -> int:
        return self.n_window + 2 * self.n_harm

    @property
    def i_zeta(self) -> int:
        return self.size - 1


def mesh_harmonics(settings: CalibrationSettings, fs: float, f_mesh: float) -> int:
    """Mesh harmonics whose transmission error calibration fits: `settings.mesh_harmonics`, or
    every one below 0.45 × the rate `fs` (Hz), at most
    :data:`dtwin.registry.N_EXCITATION_HARMONICS` (those with a registry name); `f_mesh` (Hz)."""
    return settings.mesh_harmonics or max(1, min(int(0.45 * fs / f_mesh),
                                                 N_EXCITATION_HARMONICS))


def _prepare_twin(spec: Spec, f_sun: float, kind: str | None, settings: CalibrationSettings,
                  n_harm: int, fit_shares: bool = False):
    twin = build_twin(spec, kind=kind, f_sun=f_sun)
    i_path = next((i for i, p in enumerate(twin.parts) if isinstance(p, PlanetPassTransferPath)),
                  None)
    if i_path is None:
        raise SpecError([("sensor", "the twin has no planet-pass transfer path to calibrate")])
    path = twin.parts[i_path]
    K = settings.window_terms
    if path.window_harmonics is not None:
        c = np.zeros(K)
        w = np.asarray(path.window_harmonics)[:K]
        c[: w.size] = w
    else:
        c = window_cosine_coefficients(float(path.window_exponent), K)
    twin = eqx.tree_at(lambda t: t.parts[i_path].window_harmonics, twin,
                       jnp.asarray(c, dtype=jnp.float64), is_leaf=lambda x: x is None)
    i_exc = next((i for i, p in enumerate(twin.parts) if isinstance(p, MeshExcitation)), None)
    if i_exc is None:
        twin = twin.with_parts(MeshExcitation.zeros(n_harm))
        i_exc = len(twin.parts) - 1
    else:
        old = twin.parts[i_exc]
        pad = max(0, n_harm - old.n_harmonics)

        def grow(a):
            return jnp.concatenate([a, jnp.zeros(pad)])[:n_harm]

        twin = eqx.tree_at(lambda t: t.parts[i_exc], twin,
                           MeshExcitation(grow(old.sun_cos), grow(old.sun_sin),
                                          grow(old.ring_cos), grow(old.ring_sin)))
    # θ of the excitation in units of _TE_UNIT (of the order of the parametric excitation's
    # effect at the mesh harmonics), so every θ column has a similar scale for the LM steps
    layout = _Layout(K - 1, n_harm, tuple(float(v) for v in c), max(abs(c[0]), 1e-12),
                     _TE_UNIT)
    if fit_shares:
        n = twin.n_planets
        old_shares = spec["imperfections"]["load_sharing"]
        s0 = np.ones(n) if old_shares is None else np.asarray(old_shares, float)
        i_ls = next((i for i, p in enumerate(twin.parts) if isinstance(p, MeshOffsets)), None)
        if i_ls is None:
            twin = twin.with_parts(MeshOffsets(jnp.zeros(n), jnp.zeros(n)))
            i_ls = len(twin.parts) - 1
        layout = dataclasses.replace(layout, n_share=n - 1,
                                     share_init=tuple(float(v) for v in s0 / s0[0]),
                                     f_sun=float(f_sun), i_share_part=i_ls)
    return twin, i_path, i_exc, layout


def _shares(theta, layout: _Layout):
    """The planets' relative load shares (planet 0 = 1) at θ."""
    s0 = jnp.asarray(layout.share_init, dtype=jnp.float64)
    return s0.at[1:].add(_SHARE_UNIT * theta[layout.i_share: layout.i_share + layout.n_share])


def _carrier_order_lines(kin: Kinematics, freqs, A, F) -> int:
    """How many orders ``k f_c`` below the first mesh band, k not a multiple of N, stand above
    the line threshold in the mean spectrum of the records (A, F: (rec, half, bins))."""
    a, f = A.mean(axis=(0, 1)), F.mean(axis=(0, 1))
    df = freqs[1] - freqs[0]
    count = 0
    for k in range(1, int((kin.f_mesh - 2 * kin.n_planets * kin.f_carrier) / kin.f_carrier)):
        if k % kin.n_planets == 0:
            continue
        b = int(round(k * kin.f_carrier / df))
        if b + 1 < a.size and np.max(a[b - 1: b + 2] / f[b - 1: b + 2]) > 10 ** (THRESHOLD_DB / 20):
            count += 1
    return count


def _apply(twin, theta, layout: _Layout, i_path: int, i_exc: int):
    """`twin` with the calibration vector θ written in (differentiable)."""
    c0 = jnp.asarray(layout.c_init, dtype=jnp.float64)
    c = c0.at[1:].add(layout.window_scale * theta[: layout.n_window])
    twin = eqx.tree_at(lambda t: t.parts[i_path].window_harmonics, twin, c)
    h = layout.n_harm
    te = theta[layout.n_window: layout.n_window + 2 * h] * layout.te_scale
    exc = twin.parts[i_exc]
    twin = eqx.tree_at(lambda t: (t.parts[i_exc].ring_cos, t.parts[i_exc].ring_sin), twin,
                       (exc.ring_cos + te[:h], exc.ring_sin + te[h:]))
    if layout.n_share:
        # clearances from the static balance of the twin before θ's damping (which they do not
        # depend on): linear in the shares, so forward-mode tangents stay exact
        e = load_share_offsets(twin, _shares(theta, layout), layout.f_sun)
        twin = eqx.tree_at(lambda t: t.parts[layout.i_share_part], twin, MeshOffsets(e, e))
    s = jnp.exp(theta[layout.i_zeta])
    lp = twin.lp
    lp = replace_lumped(lp, zeta_sun_planet=lp.zeta_sun_planet * s,
                        zeta_ring_planet=lp.zeta_ring_planet * s)
    return eqx.tree_at(lambda t: t.lp, twin, lp)


def _response(twin, layout, i_path, i_exc, daq, n, f_sun, settings, theta_lin):
    """The signal at `theta_lin` and its Jacobian (n, P) by forward mode through the solve."""
    fs = float(daq.sample_rate)
    solver = settings.solver or SolverOptions(periodic="auto")

    def linearise(solver):
        def sig(theta):
            tw = _apply(twin, theta, layout, i_path, i_exc)
            res = simulate(tw, duration=n / fs, f_sun=f_sun, daq=daq, discard=settings.discard,
                           solver=solver, check=False)
            return res.signal[:n], res.periodic_defect

        # evaluated eagerly, not as one compiled program: compiled, it rounds differently, and
        # the calibration's weakly determined directions then lead its fit to another optimum
        return jax.linearize(sig, jnp.asarray(theta_lin, dtype=jnp.float64))

    # one period of the gear set tiled is the response only where the start-up transient has
    # died out within the settling time (as `simulate` checks with concrete values): otherwise the
    # tiles' joins put a broadband hump under the twin's lightly damped modes. Settle longer,
    # then integrate the whole record.
    for option in settling_sequence(solver):
        (y0, defect), jvp_fn = linearise(option)
        if defect is None or float(defect) <= solver.periodic_tolerance:
            break
    # the tangents in batches: all at once, they held ~170 MB each for a 3 s record at 10 kHz
    # (5.9 GB in all for 25 of them); each batch runs the solve again
    eye = jnp.eye(layout.size)
    batch = _tangent_batch(n * daq.oversample)
    J = np.concatenate([np.asarray(jax.vmap(lambda v: jvp_fn(v)[0], in_axes=1, out_axes=1)(
        eye[:, i : i + batch])) for i in range(0, layout.size, batch)], axis=1)
    y0 = np.asarray(y0)
    if not (np.all(np.isfinite(y0)) and np.all(np.isfinite(J))):
        raise FitError("the twin's simulation failed at the "
                       + ("spec's values" if not np.any(np.asarray(theta_lin)) else
                          "calibration's values") + " (non-finite signal); check the spec with "
                       "`dtwin spec check`")
    return y0, J


def _tangent_batch(n_samples: int) -> int:
    """How many tangents of a response over `n_samples` samples of the oversampled grid are
    formed at once (at least one): `_TANGENT_BUDGET` over `_TANGENT_BYTES_PER_SAMPLE` each."""
    return max(1, _TANGENT_BUDGET // (_TANGENT_BYTES_PER_SAMPLE * n_samples))


def _family_bins(kin: Kinematics, freqs: np.ndarray) -> np.ndarray:
    """Bins (±1) of the healthy line families: k f_c below the first mesh band and
    m f_m + n f_c, |n| ≤ 10, below Nyquist."""
    df = freqs[1] - freqs[0]
    f_top = freqs[-1]
    fr = [k * kin.f_carrier for k in range(1, int((kin.f_mesh - 10 * kin.f_carrier)
                                                  / kin.f_carrier) + 1)]
    m = 1
    while m * kin.f_mesh - 10 * kin.f_carrier < f_top:
        fr += [m * kin.f_mesh + n * kin.f_carrier for n in range(-10, 11)]
        m += 1
    k = np.rint(np.asarray(fr) / df).astype(int)
    k = np.concatenate([k - 1, k, k + 1])
    mask = np.zeros(len(freqs), bool)
    mask[k[(k > 0) & (k < len(freqs))]] = True
    return mask


class _Data(eqx.Module):
    """Arrays of one fit: rows are (record, half) pairs."""

    Z0: jax.Array  # (rows, bins) complex: the model's spectra at the linearisation point
    JZ: jax.Array  # (rows, bins, P) complex
    theta_lin: jax.Array  # (P,): the linearisation point
    A: jax.Array  # measured amplitudes (rows, bins)
    F: jax.Array  # measured floors (rows, bins)
    S: jax.Array  # fit-bin weights (rows, bins)
    W: jax.Array  # response-solve weights (rows, bins): measured lines
    B: jax.Array  # knot basis (bins, knots)
    prior_sd: jax.Array  # (P,)
    smooth: float = eqx.field(static=True)
    frf_prior: float = eqx.field(static=True)


def _frf_solve(absZ, data: _Data):
    """Closed-form knot gains (dB) for the model amplitudes |Z| (variable projection)."""
    D = data.A  # measured
    lvl = _DB * (jnp.log(D + 1e-300) - jnp.log(absZ + 1e-300))
    lvl = jnp.clip(lvl, -200.0, 200.0)
    # only lines the model also has inform the response (a line the twin cannot make, e.g. an
    # alias or an unrelated tone, would otherwise drag it): weight by the model line's height
    # within 60 dB of the model's strongest line
    rel = _DB * (jnp.log(absZ + 1e-300) - jnp.log(jnp.max(absZ, axis=-1, keepdims=True)))
    W = data.W * jax.nn.sigmoid((rel + 60.0) / 3.0)
    B = data.B
    k = B.shape[1]
    BtWB = jnp.einsum("rb,bi,bj->ij", W, B, B)
    BtWy = jnp.einsum("rb,bi,rb->i", W, B, lvl)
    wsum = jnp.maximum(jnp.sum(W), 1.0)
    mean = jnp.sum(W * lvl) / wsum
    P = jnp.eye(k) / data.frf_prior**2
    if k >= 3:
        L = jnp.asarray(np.diff(np.eye(k), n=2, axis=0))
        P = P + L.T @ L / data.smooth**2
    return jnp.linalg.solve(BtWB + P, BtWy + (jnp.eye(k) / data.frf_prior**2) @ (mean *
                                                                               jnp.ones(k)))


@eqx.filter_jit
def _model_amp(theta, data: _Data):
    d = (theta - data.theta_lin).astype(data.JZ.dtype)
    Z = data.Z0 + jnp.einsum("rbp,p->rb", data.JZ, d)
    absZ = jnp.abs(Z)
    G = _frf_solve(absZ, data)
    g = 10.0 ** ((data.B @ G) / 20.0)
    return g[None, :] * absZ, G


def _residuals(theta, data: _Data):
    A_mod, _ = _model_amp(theta, data)
    F = data.F
    l_meas = jnp.log(data.A + F)
    l_mod = jnp.log(jnp.sqrt(A_mod**2 + F**2) + F)
    r = _DB * (l_meas - l_mod) * data.S
    return jnp.concatenate([r.ravel(), theta / data.prior_sd])


@eqx.filter_jit
def _residuals_and_jacobian(theta, data: _Data):
    """The residuals at `theta` and their Jacobian (forward mode), as one compiled program."""
    return _residuals(theta, data), jax.jacfwd(_residuals)(theta, data)


def _column_scales(r, Jr, n_prior: int) -> tuple[float, jax.Array]:
    """½‖r‖² and 1 / (norm of each data column of the residual Jacobian `Jr`), from the
    residuals and Jacobian at a point (the last `n_prior` rows are the prior's): the LM iterates
    on ``u = θ / scale``, in which every column has unit norm (the window's c_3 moves the
    planet-pass line ~10⁴ times more per unit than an excitation coefficient moves a mesh
    line)."""
    norms = jnp.sqrt(jnp.sum(Jr[:-n_prior] ** 2, axis=0))
    return float(0.5 * jnp.sum(r**2)), 1.0 / jnp.maximum(norms, 1e-9 * jnp.max(norms))


def _scaled_residuals(u, args):
    data, scale = args
    return _residuals(u * scale, data)


def _fit(data: _Data, theta0, max_steps: int, loss_rtol: float, run_steps: int,
         restart_rtol: float):
    """θ at the fit's end, its Levenberg–Marquardt steps (all runs), whether it stopped
    before `max_steps` with its loss settled, and its loss there (½‖r‖², prior rows included).

    A Levenberg–Marquardt run from θ0 can settle on a shallow slope, its trust region small
    and its column scales those of θ0, and crawl (the loss falling by ~1e-4 of itself per step
    for hundreds of steps) well above the minimum. The fit is therefore a sequence of runs of
    at most `run_steps` steps, each from where the last one ended with column scales taken
    there and a fresh trust region, until a run lowers the loss by no more than
    `restart_rtol` of itself (converged) or the runs' steps reach `max_steps` (not).
    """
    solver = StallStopping(rtol=1e-8, atol=1e-10, loss_rtol=loss_rtol)
    P = theta0.shape[0]
    theta = jnp.asarray(theta0)
    # one residual-and-Jacobian evaluation per run gives the loss where the last run ended and
    # the column scales of the next
    loss, scale = _column_scales(*_residuals_and_jacobian(theta, data), P)
    steps = 0
    while steps < max_steps:
        # a module-level function with the scales among the arguments: fits of equal shapes
        # (the two halves, every run) share one compilation
        sol = optx.least_squares(_scaled_residuals, solver, theta / scale, args=(data, scale),
                                 max_steps=min(run_steps, max_steps - steps), throw=False)
        steps += int(sol.stats["num_steps"])
        new = sol.value * scale
        new_loss, new_scale = _column_scales(*_residuals_and_jacobian(new, data), P)
        if not new_loss < loss:  # LM accepts only steps that lower the loss: nothing moved
            return np.asarray(theta), steps, True, float(loss)
        theta, drop, loss, scale = new, loss - new_loss, new_loss, new_scale
        if drop <= restart_rtol * (loss + drop):
            return np.asarray(theta), steps, True, float(loss)
    return np.asarray(theta), steps, False, float(loss)


# ------------------------------------------------------------------------------------ the driver
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
    if not records:
        raise RecordError("calibration needs at least one healthy record")
    recs, names = zip(*(_as_record(r) for r in records), strict=True)
    X, fs = _signal_rows(recs, channel)
    unit = _records_unit(recs, channel)
    quantity, measured = _quantity(spec, unit), unit_quantity(unit)
    n_rec, n = X.shape
    n_half = n // 2
    g = spec["gears"]
    if spec["operating"]["f_sun"] is None:
        raise SpecError([("operating.f_sun", "calibration needs the nominal input speed (Hz)")])
    kin0 = Kinematics.from_spec(spec)
    if n / fs < MIN_CARRIER_PERIODS / kin0.f_carrier * (1.0 - 1e-9):
        raise RecordError(f"{n / fs:.3g} s is shorter than {MIN_CARRIER_PERIODS:g} carrier "
                          f"periods ({MIN_CARRIER_PERIODS / kin0.f_carrier:.3g} s): the "
                          "sidebands at f_c cannot be resolved in each half; calibrate on "
                          "longer records")
    # the speed: given, or each record's (tachometer, metadata, lines), the mean over records
    # a record that holds no mesh line of this gearbox cannot calibrate it: refuse at once
    ops = [resolve_speed(r, spec, f_sun, channel=channel, fallback=False) for r in recs]
    f_sun = float(np.mean([op.f_sun for op in ops]))
    kin = Kinematics.from_gears(g["z_sun"], g["z_planet"], g["z_ring"], g["n_planets"], f_sun)
    say(f"speed {f_sun:.4f} Hz from {n_rec} record(s) ({ops[0].source})")
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
        say(f"{n_orders} carrier orders k f_c (k not a multiple of {kin.n_planets}) above the "
            "line threshold: fitting the planets' load shares")
    twin, i_path, i_exc, layout = _prepare_twin(spec, f_sun, kind, settings, n_harm, fit_shares)
    # the records' rate, not the spec's `sensor.sample_rate` (which describes other records)
    daq = daq_from_spec(spec, sample_rate=fs, snr_db=None, quantity=quantity, frf_hz=None,
                        frf_db=None)
    say(f"simulating the twin and its response to {layout.size} parameters "
        f"({n / fs:.1f} s at {fs:g} Hz)")
    theta0 = jnp.zeros(layout.size)

    def linearised(theta_lin):
        """The model's halves (the same for every record) and their response at `theta_lin`."""
        y, J = _response(twin, layout, i_path, i_exc, daq, n, f_sun, settings, theta_lin)
        _, Z = segment_spectra(y, fs, 2)  # (2, bins)
        _, JZ = segment_spectra(J.T, fs, 2)  # (P, 2, bins)
        return Z, np.moveaxis(JZ, 0, -1), np.asarray(theta_lin)  # JZ: (2, bins, P)

    lin = lin0 = linearised(theta0)
    Z0 = lin[0]
    # the noise floor as an rms: a Hann amplitude spectrum of white noise of variance σ² has
    # Rayleigh amplitudes of median sqrt(2 ln 2 · 3 σ² / n_half)
    noise_rms = float(np.sqrt(np.median(F) ** 2 * n_half / (6.0 * math.log(2.0))))
    fam = _family_bins(kin, freqs)
    strong = A > F * 10.0 ** (THRESHOLD_DB / 20.0)
    # the scored band ends where the DAQ's anti-aliasing pass band does (the spec's)
    band_top = float(spec["sensor"]["passband"]) * fs
    band = (freqs >= 0.5 * kin.f_carrier) & (freqs <= band_top)
    S = (fam[None, None, :] | strong) & band[None, None, :]
    Wl = strong & band[None, None, :]
    knots = np.geomspace(0.8 * kin.n_planets * kin.f_carrier, band_top, settings.n_knots)
    B = knot_basis(freqs, knots)
    prior = np.concatenate([np.full(layout.n_window, settings.window_prior),
                            np.full(2 * n_harm, settings.te_prior / _TE_UNIT),
                            np.full(layout.n_share, settings.share_prior / _SHARE_UNIT),
                            [settings.zeta_prior]])

    def data_for(rows_rec, rows_half, lin):
        Z, JZ, theta_lin = lin
        return _Data(
            Z0=jnp.asarray(Z[rows_half]), JZ=jnp.asarray(JZ[rows_half]),
            theta_lin=jnp.asarray(theta_lin),
            A=jnp.asarray(A[rows_rec, rows_half]), F=jnp.asarray(F[rows_rec, rows_half]),
            S=jnp.asarray(S[rows_rec, rows_half].astype(float)),
            W=jnp.asarray(Wl[rows_rec, rows_half].astype(float)), B=jnp.asarray(B),
            prior_sd=jnp.asarray(prior), smooth=settings.smooth_db,
            frf_prior=settings.frf_prior_db,
        )

    rec_idx = np.repeat(np.arange(n_rec), 2)
    half_idx = np.tile(np.arange(2), n_rec)
    bands = named_bands(kin, band_top)
    a_meas = A.reshape(-1, A.shape[-1])

    # the model's amplitudes at θ (response solved on `fit_rows`), on the rows `score_rows`
    def amp_at(theta, fit_rows, score_rows, lin):
        _, G = _model_amp(jnp.asarray(theta), data_for(rec_idx[fit_rows], half_idx[fit_rows],
                                                        lin))
        d = data_for(rec_idx[score_rows], half_idx[score_rows], lin)
        Z = d.Z0 + jnp.einsum("rbp,p->rb", d.JZ, jnp.asarray(theta - lin[2], d.JZ.dtype))
        return np.asarray(10.0 ** ((B @ np.asarray(G)) / 20.0))[None, :] * np.abs(np.asarray(Z))

    # before: the spec's twin with its best response level (one gain), scored per half
    B1 = knot_basis(freqs, knots[:1])

    def before_amp(train_half, score_half):
        tr = half_idx == train_half
        d = data_for(rec_idx[tr], half_idx[tr], lin)
        d = eqx.tree_at(lambda x: x.B, d, jnp.asarray(B1))
        _, G = _model_amp(theta0, d)
        sc = half_idx == score_half
        return float(10.0 ** (float(G[0]) / 20.0)) * np.abs(Z0[half_idx[sc]])

    def cross_validated(lin, warm):
        """The held-out gap about linearisation `lin` (fitted on each half, scored on the other
        with the linearised response) and the halves' fits, ``[(θ, data)]``. Each half is
        fitted from the linearisation point and from `warm` (the fit on all the records), and
        keeps the fit with the lower loss on its own half: a half's fit from the linearisation
        point alone can stall far above its minimum (the window and the load shares multiply
        each other), which would score the optimiser, not the model."""
        a_held = np.empty_like(a_meas)
        fits = []
        for h in (0, 1):
            tr = half_idx == h
            d = data_for(rec_idx[tr], half_idx[tr], lin)
            # each run's own final loss on this half (the fit computes it) picks the start
            theta_h = min((_fit(d, start, settings.max_steps, settings.loss_rtol,
                                settings.run_steps, settings.restart_rtol)
                           for start in (lin[2], warm)), key=lambda run: run[3])[0]
            a_held[half_idx != h] = amp_at(theta_h, tr, half_idx != h, lin)
            fits.append((theta_h, d))
        return gap(freqs, a_meas, a_held, bands), fits

    def cross_validated_in_full(fits):
        """The held-out gap of the halves' fits `fits` (:func:`cross_validated`), each half's
        values simulated in full and scored on the other half."""
        a_held = np.empty_like(a_meas)
        for h, (theta_h, d) in enumerate(fits):
            _, G = _model_amp(jnp.asarray(theta_h), d)
            a = confirmed(_calibrated_data(spec, theta_h, np.asarray(G), knots, layout, twin,
                                           i_exc, stamp))[0]
            a_held[half_idx != h] = a[half_idx != h]
        return gap(freqs, a_meas, a_held, bands)

    a_before = np.empty_like(a_meas)
    for h in (0, 1):
        a_before[half_idx != h] = before_amp(h, 1 - h)
    gap_before = gap(freqs, a_meas, a_before, bands)

    def confirmed(data):
        """Amplitudes (rows: record × half) and gap of the twin of spec `data` simulated in
        full over the records, nothing refitted."""
        cal_spec = _spec_from_data(data)
        y = np.asarray(simulate(
            build_twin(cal_spec, kind=kind, f_sun=f_sun), duration=n / fs, f_sun=f_sun,
            daq=daq_from_spec(cal_spec, sample_rate=fs, snr_db=None, quantity=quantity),
            discard=settings.discard, solver=settings.solver).signal[:n])
        a = np.abs(segment_spectra(y, fs, 2)[1])[half_idx]
        return a, gap(freqs, a_meas, a, bands)

    every = np.ones(len(half_idx), bool)
    tried: list[_Attempt] = []  # one per linearisation point
    for attempt in range(settings.relinearize + 1):
        say("final fit on all data" if attempt == 0 else
            f"final fit on all data, linearised at the fitted values ({attempt} of "
            f"{settings.relinearize})")
        d_all = data_for(rec_idx, half_idx, lin)
        theta, steps, converged, _ = _fit(d_all, lin[2], settings.max_steps, settings.loss_rtol,
                                          settings.run_steps, settings.restart_rtol)
        gap_lin = gap(freqs, a_meas, amp_at(theta, every, every, lin), bands)
        # the calibrated spec, then its confirmation by a full simulation
        _, G = _model_amp(jnp.asarray(theta), d_all)
        data = _calibrated_data(spec, theta, np.asarray(G), knots, layout, twin, i_exc, stamp)
        say("confirming: the calibrated twin simulated in full")
        a_after, gap_conf = confirmed(data)
        tried.append(_Attempt(gap_conf, theta, lin, steps, converged, data, a_after,
                              gap_conf.total - gap_lin.total, d_all, np.asarray(G)))
        say(f"confirmed gap {gap_conf.total:.2f} dB; the linearised twin's "
            f"{gap_lin.total:.2f} dB ({steps} LM steps" + ("" if converged else
                                                          ", stopped at the step limit") + ")")
        if attempt == 0:
            say("cross-validation: fitting on each half, scoring on the other")
            gap_held, held_fits = cross_validated(lin, theta)
            say(f"held-out gap {gap_before.total:.2f} dB before, {gap_held.total:.2f} dB "
                "calibrated")
        # the response is first order in the excitation and the load shares (and bilinear in
        # them and the window): where the full simulation departs from it, linearise again at
        # the fitted values and refit from there (an outer Gauss–Newton iteration)
        departs = gap_conf.total > gap_lin.total + settings.relinearize_db
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
            lin = linearised(theta)
    best = min(range(len(tried)), key=lambda i: tried[i].gap.total)
    chosen = tried[best]
    if best > 0:
        say("cross-validation again, about the chosen linearisation point")
        gap_held, held_fits = cross_validated(chosen.lin, chosen.theta)
        say(f"held-out gap {gap_held.total:.2f} dB")
    params = _intervals(chosen.theta, chosen.gains, chosen.fit_data, layout, knots, Wl, B, twin,
                        i_exc, settings)
    data, gap_conf, a_after = chosen.spec_data, chosen.gap, chosen.amplitudes
    calibrated_conf = float(gap_conf.total)
    departs = bool(chosen.departure > settings.relinearize_db)
    held_full = None
    if departs and gap_held.total < gap_before.total and calibrated_conf < gap_before.total:
        # the held-out gap scores a response the twin does not follow: cross-validate the
        # twin itself, each half's values simulated in full and scored on the other half
        say("cross-validation of the twin simulated in full (it departs from the fitted "
            "response)")
        held_full = float(cross_validated_in_full(held_fits).total)
        say(f"held-out gap simulated in full {held_full:.2f} dB")
    why = adoption(gap_before.total, gap_held.total, calibrated_conf, held_full)
    kept = bool(why)
    if kept:
        # the calibrated values fit the training half in directions the records do not
        # determine and generalise worse than the spec as written, or the twin simulated in
        # full does not bear them out (adoption): keep the spec, with the level the "before"
        # model fitted, on all the data
        say(f"the calibrated values are not adopted ({why}): keeping the spec's values, with "
            "its fitted response level")
        d_flat = eqx.tree_at(lambda x: x.B, data_for(rec_idx, half_idx, lin0), jnp.asarray(B1))
        _, G1 = _model_amp(theta0, d_flat)
        data = _kept_data(spec, float(G1[0]), knots, stamp, why)
        a_after, gap_conf = confirmed(data)
        say(f"confirmed gap of the spec as written {gap_conf.total:.2f} dB")
    data["calibration"]["heldout_gap_db"] = round(float(gap_conf.total), 3)
    # what the calibrated twin still leaves unexplained on the healthy records: discovery
    # refuses a candidate whose evidence lies there (dtwin.identify.shortfall)
    orders, excess = shortfall_lines(freqs, a_meas, a_after, kin, band_top)
    data["calibration"]["shortfall_orders"] = [round(o, 6) for o in orders]
    data["calibration"]["shortfall_db"] = [round(e, 2) for e in excess]
    return CalibrationResult(data, params, f_sun, gap_before, gap_held, gap_conf, freqs,
                             a_meas, a_before, a_after, noise_rms, list(names),
                             chosen.steps, chosen.converged, best + 1, float(chosen.departure),
                             departs, kept, calibrated_conf, held_full)


def adoption(before: float, heldout: float, confirmed: float | None,
             heldout_full: float | None = None) -> str:
    """Whether calibrated values are adopted, from the gaps (dB) of the spec as written
    (`before`: one fitted level, held out), of the calibration held out (`heldout`: the
    linearised response fitted on one half and scored on the other), of the calibrated twin
    simulated in full (`confirmed`, all data; None when not measured) and, where that twin
    departs from the linearised response, of the twin held out (`heldout_full`: each half's
    values simulated in full and scored on the other half; None when not measured). Adopted
    when:

    1. the held-out gap is below the spec's (cross-validation);
    2. the confirmed gap is below it too: the twin simulated in full bears the linearised
       response out;
    3. where measured, the held-out gap of the twin simulated in full is below it: where the
       twin departs from the linearised response, the held-out gap of 1. scores a response the
       twin does not follow, and only the twin's own cross-validation says whether the values
       generalise.

    **Returns:** "" when adopted, otherwise the reason, in words."""
    if not heldout < before:
        return (f"no closer to the held-out halves than the spec as written, {heldout:.2f} "
                f"against {before:.2f} dB")
    if confirmed is not None and not confirmed < before:
        return (f"no closer to the records than the spec as written once simulated in full, "
                f"{confirmed:.2f} against {before:.2f} dB")
    if heldout_full is not None and not heldout_full < before:
        return (f"simulated in full, no closer to the held-out halves than the spec as "
                f"written, {heldout_full:.2f} against {before:.2f} dB")
    return ""


class _Stamp(NamedTuple):
    """What every calibrated spec records of its calibration: the records' speed (Hz), rate
    (Hz), the quantity their unit names (None: the spec's stays), their names, the twin kind
    (None: the spec's)."""

    f_sun: float
    fs: float
    measured: str | None
    names: tuple[str, ...]
    kind: str | None


def _stamped(data: dict[str, Any], stamp: _Stamp) -> dict[str, Any]:
    """`data` (a spec mapping) with the records' speed, rate and quantity, the twin kind and
    the ``[calibration]`` table (`_Stamp`)."""
    sensor = data["sensor"]
    sensor["sample_rate"] = float(stamp.fs)  # the calibrated records' (knots reach 0.45 of it)
    if stamp.measured:  # what the records measure, as the calibration simulated it
        sensor["quantity"] = stamp.measured
    data["operating"]["f_sun"] = float(stamp.f_sun)
    if stamp.kind:
        data["model"]["kind"] = stamp.kind
    data["calibration"] = {"records": ", ".join(stamp.names),
                           "created_by": f"dtwin {__version__}"}
    return data


def _kept_data(spec: Spec, gain_db: float, knots, stamp: _Stamp, why: str) -> dict[str, Any]:
    """The spec as written, as a calibrated spec: its own values, a flat sensor response at
    the fitted level `gain_db` (dB at every knot), the records' speed, rate and quantity, and
    the ``[calibration]`` table saying that the calibrated values were not adopted, and `why`
    (:func:`adoption`)."""
    data = spec_to_dict(spec)
    data.pop("source", None)
    data["sensor"]["frf_hz"] = [float(v) for v in knots]
    data["sensor"]["frf_db"] = [float(gain_db)] * len(knots)
    data = _stamped(data, stamp)
    data["calibration"]["kept_spec"] = (f"the calibrated values were not adopted ({why}): the "
                                        "spec's own values, with its fitted response level")
    return data


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


def _quantity(spec: Spec, unit: str | None = None) -> str:
    """What the records measure: their channel's unit where it says (``mm/s`` → velocity,
    `dtwin.units.quantity`), else the spec's `sensor.quantity`."""
    q = unit_quantity(unit) or spec["sensor"]["quantity"]
    return "acceleration" if q == "ring_velocity" else q


def _intervals(theta, G, data: _Data, layout: _Layout, knots, Wl, B, twin, i_exc,
               settings) -> list[CalibratedParameter]:
    r, Jr = _residuals_and_jacobian(jnp.asarray(theta), data)
    r, Jr = np.asarray(r), np.asarray(Jr)
    m_data = int(np.asarray(data.S).sum())
    p = len(theta)
    n_prior = p
    rss = float(np.sum(r[:-n_prior] ** 2))
    s2 = max(rss / max(m_data - p - len(knots), 1), 1e-12)
    # data rows scaled by the residual variance; prior rows keep their unit variance
    Jd, Jp = Jr[:-n_prior], Jr[-n_prior:]
    info = Jd.T @ Jd / s2 + Jp.T @ Jp
    cov = np.linalg.pinv(info)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    prior = np.asarray(data.prior_sd)
    names = ([f"window_c{k + 1}" for k in range(layout.n_window)]
             + [f"excitation_ring_{cs}_{i + 1}" for cs in ("cos", "sin")
                for i in range(layout.n_harm)]
             + [f"load_share_{i}" for i in range(1, layout.n_share + 1)] + ["zeta_mesh"])
    joint = _joint(cov, info, prior, names)
    out = []
    c = np.asarray(layout.c_init)
    for k in range(layout.n_window):
        val = c[k + 1] + layout.window_scale * theta[k]
        out.append(CalibratedParameter(
            names[k], float(val), "1", float(layout.window_scale * sd[k]),
            float(layout.window_scale * prior[k]), bool(sd[k] < 0.5 * prior[k]),
            joint_with=joint[k]))
    exc = twin.parts[i_exc]
    h = layout.n_harm
    for j, base in enumerate((exc.ring_cos, exc.ring_sin)):
        for i in range(h):
            k = layout.n_window + j * h + i
            val = float(base[i]) + layout.te_scale * theta[k]
            out.append(CalibratedParameter(
                names[k], val, "m", float(layout.te_scale * sd[k]),
                float(layout.te_scale * prior[k]), bool(sd[k] < 0.5 * prior[k]),
                "with the response at this harmonic: one sensor sees their product",
                joint[k]))
    shares = np.asarray(_shares(jnp.asarray(theta), layout)) if layout.n_share else ()
    for i in range(layout.n_share):
        k = layout.i_share + i
        out.append(CalibratedParameter(
            names[k], float(shares[i + 1]), "1", float(_SHARE_UNIT * sd[k]),
            float(_SHARE_UNIT * prior[k]), bool(sd[k] < 0.5 * prior[k]),
            "load share relative to planet 0", joint[k]))
    k = layout.i_zeta
    z0 = float(twin.lp.zeta_ring_planet)
    out.append(CalibratedParameter("zeta_mesh", z0 * math.exp(theta[k]), "1",
                                   z0 * math.exp(theta[k]) * float(sd[k]),
                                   z0 * float(prior[k]), bool(sd[k] < 0.5 * prior[k]),
                                   "sd of the log value times the value", joint[k]))
    # response knots: covariance of the closed-form solve at the optimum
    W = np.asarray(data.W)
    BtWB = np.einsum("rb,bi,bj->ij", W, B, B)
    k_n = len(knots)
    P = np.eye(k_n) / settings.frf_prior_db**2
    if k_n >= 3:
        L = np.diff(np.eye(k_n), n=2, axis=0)
        P = P + L.T @ L / settings.smooth_db**2
    covG = np.linalg.pinv(BtWB / s2 + P)
    support = (W.sum(axis=0) @ (B > 0.05)) > 0
    for j, f in enumerate(knots):
        sdj = float(np.sqrt(max(covG[j, j], 0.0)))
        out.append(CalibratedParameter(
            f"frf_db_{j}", float(G[j]), "dB", sdj, settings.frf_prior_db,
            bool(support[j] and sdj < 3.0), f"response at {f:.6g} Hz"
            + ("" if support[j] else "; no measured line near this knot")))
    return out


def _joint(cov, info, prior, names, n_max: int = 3) -> list[tuple[tuple[str, float], ...]]:
    """For each parameter the data do not determine alone (marginal sd ≥ half the prior's) but
    do with the others held (conditional sd ``1/sqrt(info_kk)`` below half the prior's): the
    `n_max` parameters most correlated with it in the posterior, with their correlations.
    Empty for the others."""
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    cond = 1.0 / np.sqrt(np.clip(np.diag(info), 1e-300, None))
    corr = cov / np.maximum(np.outer(sd, sd), 1e-300)
    out = []
    for k in range(len(names)):
        if sd[k] < 0.5 * prior[k] or not cond[k] < 0.5 * prior[k]:
            out.append(())
            continue
        others = [j for j in np.argsort(-np.abs(corr[k])) if j != k][:n_max]
        out.append(tuple((names[j], round(float(corr[k, j]), 2)) for j in others))
    return out


def _calibrated_data(spec: Spec, theta, G, knots, layout: _Layout, twin, i_exc,
                     stamp: _Stamp) -> dict[str, Any]:
    data = spec_to_dict(spec)
    data.pop("source", None)
    c = np.asarray(layout.c_init).copy()
    c[1:] += layout.window_scale * np.asarray(theta[: layout.n_window])
    sensor = data["sensor"]
    sensor["window_harmonics"] = [float(v) for v in c]
    sensor["frf_hz"] = [float(v) for v in knots]
    sensor["frf_db"] = [float(v) for v in G]
    h = layout.n_harm
    te = np.asarray(theta[layout.n_window: layout.n_window + 2 * h]) * layout.te_scale
    exc = twin.parts[i_exc]
    mesh = data["mesh"]
    mesh["excitation_ring_cos"] = [float(v) for v in np.asarray(exc.ring_cos) + te[:h]]
    mesh["excitation_ring_sin"] = [float(v) for v in np.asarray(exc.ring_sin) + te[h:]]
    mesh["excitation_sun_cos"] = [float(v) for v in np.asarray(exc.sun_cos)]
    mesh["excitation_sun_sin"] = [float(v) for v in np.asarray(exc.sun_sin)]
    if layout.n_share:
        data["imperfections"]["load_sharing"] = [
            float(v) for v in np.asarray(_shares(jnp.asarray(theta), layout))]
    z = float(twin.lp.zeta_ring_planet) * math.exp(float(theta[layout.i_zeta]))
    z = min(max(z, 1e-6), 0.499)
    damping = data["damping"]
    damping["zeta_mesh"] = z
    damping.pop("zeta_sun_planet", None)
    damping.pop("zeta_ring_planet", None)
    return _stamped(data, stamp)


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
               named_bands(kin, float(spec["sensor"]["passband"]) * fs))
