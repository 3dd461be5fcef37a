"""Memory a command will need, checked against what the machine has free before any work starts.

A command that allocates in proportion to its inputs (samples × states of a simulation, knots ×
records of a calibration, bootstrap draws of a discovery) estimates its peak with the figures
here and calls :func:`require`, which refuses, with both figures and the option to change, a
run that would not fit in the memory available now (``MemAvailable`` of ``/proc/meminfo``, or
the free physical pages of ``os.sysconf`` elsewhere). Refusing at once is better than a
``MemoryError`` (or the kernel's OOM killer) minutes later.
"""

from __future__ import annotations

import os

from ..errors import DtwinError

__all__ = ["MemoryLimitError", "available_bytes", "calibration_bytes", "discovery_bytes",
           "format_bytes", "require", "simulation_bytes"]

#: Bytes of one float64.
FLOAT64 = 8
#: Copies of the saved solution a simulation holds at its peak (the solver's saved grid, the
#: observables taken from it, the decimation filter's input and output).
SIMULATION_COPIES = 3
#: The share of the available memory a run may plan to use (the rest: the interpreter, JAX's
#: compiled programs and other processes).
USABLE_FRACTION = 0.8


class MemoryLimitError(DtwinError, MemoryError):
    """A run would need more memory than the machine has available; the message gives both
    figures and the option to change."""


def available_bytes() -> int | None:
    """Memory available to a new allocation now (bytes): ``MemAvailable`` of ``/proc/meminfo``
    (Linux: free memory plus what the kernel can reclaim), else free physical pages ×
    page size (``os.sysconf``); None when neither is known."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (OSError, ValueError, AttributeError):
        return None


def format_bytes(n: float) -> str:
    """``1.5e9`` → ``"1.4 GiB"`` (binary units; ``"inf"`` beyond 1024 EiB)."""
    if not n < float("inf"):
        return "inf"
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if abs(n) < 1024 or unit == "EiB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.3g} EiB"


def require(need: float, *, what: str, option: str, fix: str,
            available: int | None = None) -> None:
    """Refuse a run whose estimated peak `need` (bytes) exceeds :data:`USABLE_FRACTION` of the
    memory available (`available`, default :func:`available_bytes`; unknown: not checked).

    **Arguments:** `need` (bytes); `what`: what needs it (``"the simulation (4e12 samples × 52
    values)"``); `option`: the option to change, named first in the message; `fix`: what to
    change (``"lower --sample-rate or --duration"``).

    **Raises:** :class:`MemoryLimitError`.
    """
    avail = available_bytes() if available is None else available
    if avail is None:
        return
    budget = USABLE_FRACTION * avail
    if need > budget:
        raise MemoryLimitError(
            f"{option}: {what} needs about {format_bytes(need)} of memory, but "
            f"{format_bytes(avail)} is available ({100 * USABLE_FRACTION:.0f} % of it usable: "
            f"{format_bytes(budget)}); {fix}")


def simulation_bytes(duration: float, sample_rate: float, n_dof: int, *, oversample: int = 4,
                     n_observables: int = 8) -> float:
    """Peak memory (bytes) of a simulation: the state (``2 n_dof`` values) and the observables
    saved at every point of the internal grid (``duration × sample_rate × oversample``
    points), :data:`SIMULATION_COPIES` times, in float64.

    **Arguments:** `duration` (s) of the record; `sample_rate` (Hz) of the DAQ; `n_dof`
    degrees of freedom of the twin; `oversample`: internal rate over the DAQ's
    (:class:`dtwin.simulation.simulate.DAQ`); `n_observables`: values saved besides the state.
    """
    points = float(duration) * float(sample_rate) * oversample
    return points * (2 * n_dof + n_observables) * FLOAT64 * SIMULATION_COPIES


#: Bytes a calibration holds per point of a record's oversampled grid besides its tangents:
#: the linearised solve's own record of the simulation. Measured (peak RSS, paper-bench, the
#: bundled bench_healthy at 5 kHz): 1.89 GB for 2 s and 1.94 GB for 4 s, the tangents filling
#: their 1 GiB budget in both (17 and 8 at once), so ≈ 2.7 kB a point; rounded up.
CALIBRATION_BYTES_PER_POINT = 3000
#: What one tangent of the response takes per point, and the budget the tangents are formed
#: within (`dtwin.identify.calibrate`: ``_TANGENT_BYTES_PER_SAMPLE``, ``_TANGENT_BUDGET``): at
#: least one tangent is formed at once, whatever its size.
TANGENT_BYTES_PER_POINT, TANGENT_BUDGET = 1500, 2**30
#: Columns (fitted parameters) of a record's Jacobian a calibration or a discovery keeps, at
#: most (each a float64 per sample).
JACOBIAN_COLUMNS = 100


def calibration_bytes(n_samples: int, *, oversample: int = 4) -> float:
    """Peak memory (bytes) of calibrating on one record of `n_samples` samples: the linearised
    solve (:data:`CALIBRATION_BYTES_PER_POINT` per point of the oversampled grid), one batch of
    tangents (the budget, or one tangent when a single one exceeds it) and the record's
    Jacobian (:data:`JACOBIAN_COLUMNS` columns)."""
    points = float(n_samples) * oversample
    return (points * CALIBRATION_BYTES_PER_POINT
            + max(float(TANGENT_BUDGET), TANGENT_BYTES_PER_POINT * points)
            + float(n_samples) * JACOBIAN_COLUMNS * FLOAT64)


def discovery_bytes(duration: float, sample_rate: float, n_dof: int, *,
                    oversample: int = 4) -> float:
    """Peak memory (bytes) of a discovery on one record: the twin simulated over the whole
    record (:func:`simulation_bytes`, as when its response is not periodic) and the responses
    of the candidates' parameters (:data:`JACOBIAN_COLUMNS` signals of the record's length)."""
    return (simulation_bytes(duration, sample_rate, n_dof, oversample=oversample)
            + float(duration) * float(sample_rate) * JACOBIAN_COLUMNS * FLOAT64)
