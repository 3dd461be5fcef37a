"""Settings of a calibration (:class:`CalibrationSettings`, :func:`dtwin.identify.calibrate.calibrate`)."""

from __future__ import annotations

import dataclasses
import math

from dtwin.errors import SpecError
from dtwin.model.registry import N_EXCITATION_HARMONICS, N_WINDOW_TERMS
from dtwin.simulation.simulate import SolverOptions

__all__ = ["CalibrationSettings", "window_terms_for"]


def window_terms_for(n_planets: int) -> int:
    r"""Cosine terms of the planet-angle window a calibration fits by default: ``2 N + 1``
    (``c_0 … c_{2N}``) for `n_planets` N, at most :data:`dtwin.model.registry.N_WINDOW_TERMS`.

    Planets equally loaded and equally spaced add the window's harmonics ``k`` that are not
    multiples of N to zero; what a fixed sensor sees of the window are its harmonics ``N`` and
    ``2N`` (and higher): the planet-pass lines ``N f_c`` and ``2 N f_c`` of the static mesh
    force and the sidebands ``m f_m ± N f_c``, ``m f_m ± 2 N f_c`` of the dynamic one
    (McFadden & Smith 1985, "An explanation for the asymmetry of the modulation sidebands about
    the tooth meshing frequency in epicyclic gear vibration", Proc. IMechE C 199(1)). The
    terms below ``2 N`` that are not multiples of N carry unequal sharing and spacing. A fixed
    count fits one gear set: seven terms reach ``2 N`` for three planets but stop short of
    the second planet pass of four (``8 f_c``), whose line then goes unmodelled.
    """
    return min(2 * int(n_planets) + 1, N_WINDOW_TERMS)


@dataclasses.dataclass(frozen=True)
class CalibrationSettings:
    """Settings of :func:`calibrate` (all optional).

    - `window_terms`: K, cosine terms of the window (``c_0 … c_{K-1}``); None (default):
      :func:`window_terms_for` the gear set, ``2 N + 1`` for N planets.
    - `n_knots`: knots of the sensor frequency response, log-spaced from 0.8 N f_c to the top
      of the pass band (the spec's ``[sensor] passband`` × the rate).
    - `mesh_harmonics`: mesh harmonics with a fitted excitation, at most
      :data:`dtwin.model.registry.N_EXCITATION_HARMONICS` (None: all below 0.45 × rate, up to that).
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
    - `solver`: `dtwin.simulation.simulate.SolverOptions` of the simulations. None: the linearised
      response is one period of the gear set after a settling time, tiled
      (``SolverOptions(periodic="auto")``, which integrates the whole record when the twin is
      not periodic at constant speed), and the confirmation integrates the whole record.
    - `relinearize`, `relinearize_db`: when the confirmation's gap exceeds the linearised
      response's gap at the fitted values by more than `converge_db` (dB), or is not below
      the spec as written's held-out gap, the response is linearised again there and the
      final fit rerun from there, at most `relinearize` times;
      the linearisation whose calibrated twin confirms with the smallest gap is kept (module
      docstring, "Linearisation"); a kept calibration whose full simulation still departs by
      more than `relinearize_db` is reported as departing and cross-validated in full; one
      linearisation moves ``log zeta_mesh`` by at most
      :func:`~dtwin.identify.calibration_model.zeta_step` of `relinearize_db`.
    - `converge_db`: the linearisation is repeated (at most `relinearize` times) while the
      confirmation's gap exceeds the linearised response's by more than this (dB; 0.1, the
      resolution every gap is reported to): an outer Gauss–Newton iteration runs until the
      full twin and the response it was fitted through agree, not until they disagree badly.
    """

    window_terms: int | None = None
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
    converge_db: float = 0.1

    def __post_init__(self):
        if self.load_sharing not in ("auto", "on", "off"):
            raise SpecError([("load_sharing", "must be 'auto', 'on' or 'off', got "
                              f"{self.load_sharing!r}")])
        if self.window_terms is not None and self.window_terms < 2:
            raise SpecError([("window_terms", "needs at least 2 cosine terms")])
        if self.window_terms is not None and self.window_terms > N_WINDOW_TERMS:
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
        if self.relinearize < 0 or not all(math.isfinite(v) and v >= 0 for v in (
                self.relinearize_db, self.converge_db)):
            raise SpecError([("relinearize/relinearize_db/converge_db", "relinearize must be "
                              f">= 0, relinearize_db and converge_db numbers >= 0 dB, got "
                              f"{self.relinearize!r}, {self.relinearize_db!r}, "
                              f"{self.converge_db!r}")])
        if self.discard < 0 or self.max_steps < 1:
            raise SpecError([("discard/max_steps", "discard must be >= 0 s and max_steps >= 1")])
