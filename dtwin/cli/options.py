"""What every command of the CLI shares: options, the one gearbox loader, checks of values, the
record reader and the output tail ("a table, or ``--json``, and ``--out DIR``").

A command module declares its options with the factories here (``PRESET``, ``SPEC``, ``JSON``,
``out_option(...)``, ``FORCE``), checks every value before any work starts (:func:`positive`,
:func:`choice`, :func:`check_out`, ...), and ends with :func:`emit`, which prints the table or
the JSON and writes the result files into ``--out`` through a staged
:class:`~dtwin.io.output.OutputFolder` (the files appear together with their manifest, or not
at all). Every failure is a :class:`~dtwin.errors.DtwinError` whose message names the option
and says what to change.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import typer

from ..errors import RecordError, SpecError
from ..simulation.speed_range import check_input_speed

PRESETS = ("paper-sim", "paper-bench", "paper-like", "lin-parker")
"""The bundled presets (``dtwin/spec/presets``); kept equal to :data:`dtwin.spec.PRESETS` by a test."""

_PRESET_HELP = "Bundled gearbox: " + ", ".join(PRESETS) + "."


class OptionError(SpecError):
    """A command-line value is out of range or not understood; the message names the option.

    A :class:`~dtwin.errors.SpecError` (the CLI's convention for bad settings: ``problems``
    holds ``(option, message)``), printed as ``OPTION: MESSAGE``.
    """

    def __init__(self, option: str, message: str):
        self.option = option
        self.problems = [(option, message)]
        Exception.__init__(self, f"{option}: {message}")



# --- option factories (each call gives a fresh typer.Option) ------------------------------------


def preset_option(help: str = _PRESET_HELP) -> Any:
    return typer.Option(None, "--preset", help=help)


def spec_option(help: str = "Gearbox spec file (TOML); see docs/spec.md.") -> Any:
    return typer.Option(None, "--spec", help=help)


def json_option(help: str = "Print the result as JSON on stdout (nothing else on stdout).") -> Any:
    return typer.Option(False, "--json", help=help)


def out_option(files: str = "result files", required: bool = False) -> Any:
    return typer.Option(... if required else None, "--out",
                        help=f"Write {files} and manifest.json into this folder (atomically: "
                        "all of them or none).")


def force_option(help: str = "Overwrite a finished result in --out.") -> Any:
    return typer.Option(False, "--force", help=help)


def export_force_option() -> Any:
    """``--force`` of a command that also writes an ``--export`` file."""
    return force_option("Overwrite a finished result in --out and the --export file.")


def export_option(what: str) -> Any:
    """``--export FILE``: `what` (the arrays and the formats a command writes) to one file."""
    return typer.Option(None, "--export", help=f"Also write {what}")


def channel_option() -> Any:
    return typer.Option("0", "--channel", help="Channel name or index.")


def splits_option(default_when: str, cost: str = "One more fit.") -> Any:
    """``--splits/--no-splits``: fit both ends of a calibrated spec's excitation/response split
    (:mod:`dtwin.identify.split`); on by default where `default_when`."""
    return typer.Option(
        None, "--splits/--no-splits",
        help="With a calibrated spec, also fit the other end of its excitation/response split "
             "(the stiffness waveform's excitation, a flat response), which a healthy record "
             "cannot tell apart and a faulty one can; the split the record prefers is "
             f"reported (default: on where {default_when}). {cost}")


def sample_rate_option() -> Any:
    return typer.Option(None, "--sample-rate", help="Sampling rate (Hz) if the file states none.")


_SPEED_RULE = ("otherwise the --tacho channel's (or the record's own tachometer), the record's "
               "metadata f_sun, the speed its mesh lines give (every mesh harmonic and its "
               "carrier sidebands jointly, within 5 % of the spec's speed), or the spec's "
               "operating.f_sun, in that order; a speed the record's lines contradict is "
               "warned about, naming the lines (docs/records.md, 'The input speed').")


def f_sun_option(help: str = "Input (sun) speed in Hz (1800 rpm = 30 Hz); ") -> Any:
    """``--f-sun HZ``: the input speed; without it, the one rule of
    :func:`dtwin.identify.operating_point.resolve_speed` (``_SPEED_RULE``)."""
    return typer.Option(None, "--f-sun", help=help + _SPEED_RULE)


def tacho_option() -> Any:
    """``--tacho CHANNEL[:PPR[:SHAFT]]``: a channel of the record holding tachometer pulses."""
    return typer.Option(
        None, "--tacho",
        help="Tachometer channel of the record (name or index), taken out of its channels: "
             "CHANNEL, CHANNEL:PPR (pulses per revolution, default 1) or CHANNEL:PPR:SHAFT "
             "(sun, the default, or carrier). Its mean speed is the input speed unless "
             "--f-sun is given.")


def tacho_reading(text: str | None) -> dict[str, Any]:
    """``--tacho CHANNEL[:PPR[:SHAFT]]`` as the tachometer arguments of
    :func:`dtwin.io.readers.read_record` (empty without one)."""
    if text is None:
        return {}
    parts = [p.strip() for p in str(text).split(":")]
    if not parts[0] or len(parts) > 3:
        raise OptionError("--tacho", f"use CHANNEL, CHANNEL:PPR or CHANNEL:PPR:SHAFT (e.g. "
                          f"tacho:1:sun), got {text!r}")
    ppr = 1
    if len(parts) > 1:
        if not parts[1].isdigit() or int(parts[1]) < 1:
            raise OptionError("--tacho", f"PPR (pulses per revolution) must be a whole number "
                              f"≥ 1, got {parts[1]!r}")
        ppr = int(parts[1])
    shaft = parts[2] if len(parts) > 2 else "sun"
    choice("--tacho", shaft, ("sun", "carrier"))
    ch: str | int = int(parts[0]) if parts[0].lstrip("-").isdigit() else parts[0]
    return {"tacho": ch, "tacho_ppr": ppr, "tacho_shaft": shaft}


# --- checks of values ---------------------------------------------------------------------------


def finite(option: str, value: float | None) -> float | None:
    """`value` unless it is NaN or infinite (None passes)."""
    if value is not None and not math.isfinite(value):
        raise OptionError(option, f"must be a finite number, got {value}")
    return value


def positive(option: str, value: float | None, *, allow_zero: bool = False,
             unit: str = "") -> float | None:
    """`value` if it is a finite number > 0 (>= 0 with `allow_zero`); None passes."""
    if value is None:
        return None
    finite(option, value)
    if value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise OptionError(option, f"must be {bound}{' ' + unit if unit else ''}, got {value:g}")
    return value


def at_least(option: str, value: int | None, low: int) -> int | None:
    """An integer option of at least `low` (None passes)."""
    if value is not None and value < low:
        raise OptionError(option, f"must be at least {low}, got {value}")
    return value


def whole_number(text: Any) -> int:
    """The value of a count option (``typer.Option(..., parser=whole_number)``): an integer,
    also written as a whole number in decimal or scientific notation (``1000``, ``1e3``,
    ``1_000``), so that ``--n-boot 1e9`` reaches the option's range check (:func:`count`)
    rather than a bare "not an integer".

    **Raises:** ``ValueError`` (a usage error naming the option) for text that is not a whole
    number (``2.5``, ``inf``, ``abc``, or beyond 10^4000)."""
    if isinstance(text, bool):
        raise ValueError(f"{text!r} is not a whole number")
    if isinstance(text, int):
        return text
    t = str(text).strip()
    try:
        return int(t)
    except ValueError:
        pass
    import decimal

    try:
        d = decimal.Decimal(t)
        if not (d.is_finite() and d == d.to_integral_value()) or abs(d.adjusted()) > 4000:
            raise ValueError
        return int(d)
    except (ArithmeticError, ValueError):
        raise ValueError(f"{t!r} is not a whole number") from None


def count(option: str, value: int | None, low: int, high: int, why: str = "") -> int | None:
    """An integer option in the closed range [low, high] (None passes); `why` (what the upper
    bound protects: run time, memory) follows the range in the message."""
    if value is not None and not low <= value <= high:
        shown = str(value)
        if len(shown) > 16:  # 1e30, not thirty-one digits
            import decimal

            shown = f"{decimal.Decimal(value):.3e}"
        raise OptionError(option, f"must lie in [{low}, {high}], got {shown}"
                          + (f": {why}" if why else ""))
    return value


#: Most solver steps a fit accepts (``--max-steps`` of identify and fleet identify).
MAX_SOLVER_STEPS = 1000


def solver_steps(value: int) -> int | None:
    """``--max-steps`` of a fit in [1, :data:`MAX_SOLVER_STEPS`]."""
    return count("--max-steps", value, 1, MAX_SOLVER_STEPS,
                 "each step is one Jacobian of the twin (seconds to minutes), and a fit that has "
                 "not converged in a thousand steps will not: free fewer parameters or use more "
                 "--starts")


def starts_and_refine(starts: int, refine: int, names: Sequence[str]) -> None:
    """``--starts`` in [1, 3^p] (the start grid of `names`, the p free parameters, holds 0 and
    the corners and edges of ``{-s, 0, s}^p``: 3^p points) and ``--refine`` in [1, --starts]."""
    grid = 3 ** len(names)
    count("--starts", starts, 1, grid, f"the start grid of {len(names)} free parameter(s) "
          f"holds {grid} points (0 and the corners and edges of {{-s, 0, s}}^{len(names)})")
    count("--refine", refine, 1, starts, "it refines the best of the --starts")


def in_range(option: str, value: float | None, low: float, high: float,
             what: str = "") -> float | None:
    """`value` in the closed interval [low, high] (None passes)."""
    if value is None:
        return None
    finite(option, value)
    if not low <= value <= high:
        raise OptionError(option, f"must lie in [{low:g}, {high:g}]{' ' + what if what else ''}, "
                          f"got {value:g}")
    return value


#: Largest seed of a random-number generator a command accepts (``--seed``): 2^32 − 1.
MAX_SEED = 2**32 - 1

#: Longest record a simulating command accepts (``--duration``, s).
MAX_DURATION_S = 3600.0
#: Longest start-up transient a simulating command simulates and drops (``--discard``, s).
MAX_DISCARD_S = 60.0


def simulated_span(duration: float, discard: float) -> None:
    """``--duration`` in (0, :data:`MAX_DURATION_S`] s and ``--discard`` in [0,
    :data:`MAX_DISCARD_S`] s, the two lengths a simulating command integrates."""
    positive("--duration", duration, unit="s")
    if duration > MAX_DURATION_S:
        raise OptionError("--duration", f"must lie in (0, {MAX_DURATION_S:g}] s, got "
                          f"{duration:g}: the twin is integrated over it at several times the "
                          "sampling rate (an hour is already hours of solving)")
    in_range("--discard", discard, 0.0, MAX_DISCARD_S, "s (the start-up transient the twin "
             "simulates and drops; it settles within seconds)")


def choice(option: str, value: str | None, allowed: Sequence[str]) -> str | None:
    """`value` if it is one of `allowed` (None passes), else an error listing them."""
    if value is not None and value not in allowed:
        import difflib

        close = difflib.get_close_matches(str(value), list(allowed), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise OptionError(option, f"unknown value {value!r}{hint}; use one of "
                          f"{', '.join(allowed)}")
    return value


def band(option: str, value: tuple[float, float] | None,
         nyquist: float | None = None) -> tuple[float, float] | None:
    """A frequency band LOW HIGH (Hz) with 0 <= LOW < HIGH (<= `nyquist` if given)."""
    if value is None:
        return None
    lo, hi = value
    finite(option, lo)
    finite(option, hi)
    if not 0 <= lo < hi:
        raise OptionError(option, f"needs 0 <= LOW < HIGH (Hz), got {lo:g} {hi:g}")
    if nyquist is not None and hi > nyquist:
        raise OptionError(option, f"HIGH = {hi:g} Hz lies above Nyquist ({nyquist:g} Hz, half "
                          "the record's sampling rate); lower it")
    return (float(lo), float(hi))


def input_speed_option(option: str, value: float | None) -> float | None:
    """An input (sun) speed in Hz within :data:`dtwin.simulation.speed_range.F_SUN_MAX`
    (:func:`dtwin.simulation.speed_range.check_input_speed`); a value that looks like rpm gets a hint."""
    if value is None:
        return None
    try:
        return check_input_speed(value, option)
    except SpecError as e:
        raise OptionError(option, e.problems[0][1]) from None


def existing_file(option: str, path: Path | None) -> Path | None:
    """`path` if it names a readable file (None passes)."""
    if path is None:
        return None
    if not path.exists():
        raise OptionError(option, f"{path} does not exist; check the path")
    if path.is_dir():
        raise OptionError(option, f"{path} is a folder; give a file")
    if not os.access(path, os.R_OK):
        raise OptionError(option, f"{path} cannot be read (permissions); fix them or copy it")
    return path


def check_out(out: Path | None, force: bool, *, option: str = "--out") -> Path | None:
    """Check an output folder before any work: not a file, creatable and writable, and not
    holding a finished result (``manifest.json``) unless `force`."""
    if out is None:
        return None
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OptionError(option, f"{out} is a file, not a folder; give a folder (it is created "
                          "if missing)")
    probe = out
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise OptionError(option, f"{probe} is a file, so {out} cannot be created; choose "
                          "another folder")
    if not _writable(probe):
        raise OptionError(option, f"{probe} is not writable; choose a folder you can write to")
    if not force and (out / "manifest.json").exists():
        from ..errors import OutputExistsError

        raise OutputExistsError(f"{option}: {out} already holds a result (manifest.json); choose "
                                "another folder or pass --force to overwrite")

    return out


def _writable(folder: Path) -> bool:
    if not os.access(folder, os.W_OK | os.X_OK):
        return False
    import tempfile

    try:  # os.access says yes to root and on some network file systems: try it
        fd, tmp = tempfile.mkstemp(prefix=".dtwin-probe-", dir=folder)
    except OSError:
        return False
    os.close(fd)
    os.unlink(tmp)
    return True


def free_names(option: str, text: str) -> list[str]:
    """Registry names of a ``--free`` list (:func:`dtwin.identify.fit.check_free`); an unknown
    name is a :class:`~dtwin.errors.ParameterError` that names the option."""
    from dtwin.identify.fit import check_free

    from ..errors import ParameterError

    try:
        return check_free(text)
    except ParameterError as e:
        raise ParameterError(f"{option}: {e}") from None


# --- the gearbox --------------------------------------------------------------------------------



@dataclasses.dataclass(frozen=True)
class Gearbox:
    """A validated spec with where it came from.

    **Fields:** `spec` (:class:`dtwin.spec.Spec`), `source` (preset name or file path),
    `file` (the spec file, an input of the run, or None for a preset).
    """

    spec: Any
    source: str
    file: Path | None = None

    def lumped(self) -> Any:
        """Lumped parameters (:func:`dtwin.spec.lumped_from_spec`)."""
        from ..spec import lumped_from_spec

        return lumped_from_spec(self.spec)

    def spec_dict(self) -> dict[str, Any]:
        from ..spec import spec_to_dict

        return spec_to_dict(self.spec)


def load_gearbox(preset: str | None, spec_file: Path | None, *, required: bool = True,
                 planets: int | None = None, presets: Sequence[str] = PRESETS,
                 why: str = "this command needs the gearbox") -> Gearbox | None:
    """The gearbox of ``--preset NAME`` or ``--spec FILE`` (the one loader of the CLI).

    **Arguments:** `required`: refuse when neither is given (else return None); `planets`:
    replace ``gears.n_planets`` (equally spaced planets; the geometry checks still apply);
    `presets`: the presets this command accepts; `why`: said when the gearbox is missing.

    **Raises:** :class:`OptionError` / :class:`~dtwin.errors.SpecError` naming what to change.
    """
    from .. import spec as spec_mod

    if preset is not None and spec_file is not None:
        raise OptionError("--preset/--spec", "give one of --preset NAME or --spec FILE, not both")
    if preset is None and spec_file is None:
        if required:
            raise OptionError("--preset/--spec", f"{why}: pass --preset NAME "
                              f"({', '.join(presets)}) or --spec FILE")
        return None
    if preset is not None:
        choice("--preset", preset, presets)
        spec, source, file = spec_mod.preset(preset), preset, None
    else:
        existing_file("--spec", spec_file)
        spec, source, file = spec_mod.load_spec(spec_file), str(spec_file), Path(spec_file)
    if planets is not None:
        at_least("--planets", planets, 1)
        data = spec_mod.spec_to_dict(spec)
        data.pop("source", None)
        data["gears"]["n_planets"] = planets
        data.get("imperfections", {}).pop("planet_position_errors", None)
        spec = spec_mod.load_spec(data)
    return Gearbox(spec, source, file)


# --- records ------------------------------------------------------------------------------------


def channel_token(channel: str) -> str | int:
    """``"2"`` → 2 (an index), anything else stays a name."""
    channel = channel.strip()
    if not channel:
        raise OptionError("--channel", "is empty; give a channel name or index (0 is the first)")
    return int(channel) if channel.lstrip("-").isdigit() else channel



def read_record(path: Path, sample_rate: float | None = None, tacho: str | None = None,
                **kwargs: Any) -> Any:
    """Read a record file (read-only) with :func:`dtwin.io.readers.read_record`; `tacho`: the
    ``--tacho`` text (:func:`tacho_reading`)."""
    from ..errors import ChannelError
    from ..io.readers import read_record as _read

    existing_file("RECORD", Path(path))
    positive("--sample-rate", sample_rate, unit="Hz")
    reading = tacho_reading(tacho)
    try:
        return _read(path, sample_rate=sample_rate, **reading, **kwargs)
    except ChannelError as e:
        if reading:
            raise ChannelError(f"--tacho: {e}") from None
        raise


def check_channel(record: Any, channel: str | int) -> None:
    """Refuse a channel the record does not have, listing those it has."""
    try:
        record.index(channel)
    except (KeyError, IndexError, ValueError):
        raise RecordError(f"--channel: unknown channel {channel}; the record has "
                          f"{', '.join(map(str, record.channels))} (names or indices 0.."
                          f"{len(record.channels) - 1})") from None


def check_fit_memory(record: Any, spec: Any, path: Any, *, command: str,
                     records: Sequence[Any] = ()) -> None:
    """Refuse, before any work, a record whose calibration or discovery would not fit in the
    memory available (:mod:`dtwin.simulation.memory`; issue 53: calibrate on 60 s at 25.6 kHz took more
    than 12 GB and was killed). `command`: ``calibrate`` (the linearised solve and its
    tangents, :func:`dtwin.simulation.memory.calibration_bytes`, plus the Jacobians of the `records`
    read before) or ``discover`` (:func:`dtwin.simulation.memory.discovery_bytes`).

    **Raises:** :class:`dtwin.simulation.memory.MemoryLimitError` naming the record, both figures and
    what to change."""
    from ..simulation.memory import (
        FLOAT64,
        JACOBIAN_COLUMNS,
        calibration_bytes,
        discovery_bytes,
        require,
    )

    try:
        oversample = int(spec["sensor"]["oversample"])
    except (KeyError, TypeError, ValueError):
        oversample = 4
    n, fs = int(record.n_samples), float(record.sample_rate)
    if command == "calibrate":
        need = calibration_bytes(n, oversample=oversample) + sum(
            float(r.n_samples) * JACOBIAN_COLUMNS * FLOAT64 for r in records)
        what = (f"calibrating on {n / fs:.4g} s at {fs:g} Hz ({n * oversample:.3g} points of "
                f"the twin's {oversample}× oversampled grid: the linearised solve and its "
                "tangents)")
    else:
        n_dof = 3 * (int(spec["gears"]["n_planets"]) + 3) + 4
        need = discovery_bytes(n / fs, fs, n_dof, oversample=oversample)
        what = (f"discovering on {n / fs:.4g} s at {fs:g} Hz (the twin simulated over the whole "
                f"record, {n * oversample:.3g} points, and the candidates' responses)")
    require(need, what=what, option=str(path),
            fix=f"{command} on a shorter cut of the record (a few seconds are enough: 8 carrier "
                "periods or more) or on one resampled to a lower rate")


def checked_record(record: Any, channel: str | int | Sequence[str | int] | None, spec: Any = None,
                   f_sun: float | None = None, *, fit: bool = False) -> Any:
    """The shared check of a record before an analysis (:func:`dtwin.io.validate.usable_record`):
    refuse what no analysis can use (and, for fits, what degrades one), warn with figures
    otherwise. `spec` and `f_sun` (Hz) give the mesh and carrier frequencies of the checks; with
    `fit` and no `f_sun`, the speed of :func:`speed_hint` (tachometer, metadata or the spec's).

    **Returns:** the record, unchanged.
    """
    from ..io.validate import usable_record
    from .logs import warn

    f_mesh = f_carrier = None
    if fit and spec is not None and f_sun is None:  # the rate and length a fit needs
        f_sun = speed_hint(record, spec)
    if spec is not None and f_sun is not None:
        from ..model.gears import characteristic_frequencies

        fr = characteristic_frequencies(spec.gear_set(), float(f_sun))
        f_mesh, f_carrier = float(fr["f_mesh"]), float(fr["f_carrier"])
    chans = None if channel is None else (
        [channel] if isinstance(channel, (str, int)) else list(channel))
    if chans is not None:
        for c in chans:
            check_channel(record, c)
    for p in usable_record(record, channels=chans, f_mesh=f_mesh, f_carrier=f_carrier, fit=fit):
        warn(p.message)
    return record


def speed_hint(record: Any, spec: Any) -> float | None:
    """The speed (Hz) the record checks use when none is given: the tachometer's, the record's
    metadata ``f_sun`` or the spec's ``operating.f_sun``, without the spectrum estimate (the
    fits estimate it from the lines, and :func:`check_speed_against_lines` checks the first
    two)."""
    from dtwin.identify.operating_point import resolve_speed

    op = resolve_speed(record, spec, estimate=False, check=False, required=False)
    return None if op is None else op.f_sun


#: A ``--f-sun`` further than this (relative) from the speed of the record's lines is refused.
GIVEN_SPEED_TOLERANCE = 0.01


def check_speed_against_lines(record: Any, spec: Any, f_sun: float | None, channel: str | int,
                              path: Any) -> Any:
    """The shared check of a fit's record against its spec's mesh lines, before any fit
    (``identify``, ``severity``, ``calibrate``, ``discover``): the speed the fit would use
    (``--f-sun``, the tachometer or the record's metadata) is checked against the record's
    lines (:func:`dtwin.identify.operating_point.check_speed`).

    - The record shows no mesh line at that speed nor near the spec's: refused (no fit can
      answer: it would run for minutes to "not determined"), except under a tachometer's speed:
      a speed that varies within the record (which the tachometer follows) smears the lines,
      so that is a warning.
    - ``--f-sun`` more than :data:`GIVEN_SPEED_TOLERANCE` off the lines' speed: refused (a fit
      at a wrong speed runs for minutes and ends at a bound), naming both speeds.
    - A smaller disagreement, or a tachometer or metadata speed the lines contradict: a
      warning naming the lines.

    - Without any of those speeds (the fit estimates it from the lines): the record's lines
      are searched near the spec's speed (:func:`dtwin.identify.operating_point.spectrum_speed`,
      the fit's own estimate) and a record without any is refused the same way.

    **Returns:** the speed checked (:class:`~dtwin.identify.operating_point.OperatingPoint`:
    given, tachometer or metadata), or None when the fit is to estimate it.
    """
    from dtwin.identify.operating_point import (
        SpeedDisagreementError,
        check_speed,
        nominal_speed,
        resolve_speed,
        spectrum_speed,
    )

    from .logs import warn

    no_line = f"{path}: the record holds no line at the spec's mesh frequency"
    op = resolve_speed(record, spec, f_sun, channel=channel, estimate=False, check=False,
                       required=False)
    if op is None or op.method == "spec":  # the fit takes the speed from the record's lines
        nominal = nominal_speed(spec)
        if nominal:
            try:
                spectrum_speed(record.channel(channel), record.sample_rate, spec, nominal)
            except SpeedDisagreementError:
                pass  # lines there, at odds: the fit's estimate says so, harmonic by harmonic
            except RecordError as e:
                if "stands above the noise" not in str(e):
                    raise RecordError(f"{path}: {e}") from None
                raise RecordError(f"{no_line}: {e}") from None
        return None
    if op.method == "tacho" and _tacho_varies(record):
        return op  # a run-up or coast-down: no line stands at its mean speed; the fit follows it
    what = {"given": "--f-sun", "tacho": "the tachometer's speed",
            "metadata": "the record's metadata f_sun"}[op.method]
    res = check_speed(record, spec, op.f_sun, channel=channel, what=what)
    if res.agrees:
        return op
    if res.f_record is None and op.method != "tacho":
        fix = {"given": "--f-sun", "metadata": "the record's metadata f_sun"}[op.method]
        raise RecordError(f"{no_line}: {res.message}; check the spec's tooth numbers and "
                          f"speed, the channel (--channel) and {fix}")
    if op.method == "given" and abs(res.f_record / op.f_sun - 1) > GIVEN_SPEED_TOLERANCE:
        raise RecordError(f"{path}: {res.message}; drop --f-sun (the speed is then taken from "
                          "the record) or correct it")
    warn(f"{path}: {res.message}")
    return op


def _tacho_varies(record: Any) -> bool:
    """Whether the record's tachometer speed changes by more than
    :data:`dtwin.signal.order.RUNUP_SPEED_CHANGE` of its median within the record (a run-up or
    coast-down): its mesh lines are then smeared over the speed range, and the mean speed has
    none to be checked against."""
    from dtwin.signal.order import RUNUP_SPEED_CHANGE, tacho_speed_range

    lo, hi, med = tacho_speed_range(record.tacho, record.sample_rate, record.tacho_ppr)
    return med > 0 and (hi - lo) / med > RUNUP_SPEED_CHANGE


class progress_line:
    """Show the progress a library prints on stdout (diffrax's ``12.34%`` lines) as one
    updating line on stderr, ``LABEL: 12.3 %``; stdout stays clean for tables and JSON.

    ``with progress_line("simulating", enabled=...) as shown:`` gives `shown` (pass it on as
    the library's ``progress`` flag): False when disabled or under ``--quiet``.
    """

    def __init__(self, label: str, *, enabled: bool = True):
        from .logs import is_quiet

        self.label = label
        self.enabled = enabled and not is_quiet()
        self._buf = ""
        self._shown = False

    def __enter__(self) -> bool:
        import contextlib
        import sys

        self._stack = contextlib.ExitStack()
        if self.enabled:
            self._err = sys.stderr
            self._stack.enter_context(contextlib.redirect_stdout(self))  # type: ignore[arg-type]
        return self.enabled

    def write(self, text: str) -> int:
        self._buf += text
        *lines, self._buf = self._buf.split("\n")
        for line in lines:
            line = line.strip()
            if line:
                self._err.write(f"\r{self.label}: {line.replace('%', ' %')}   ")
                self._err.flush()
                self._shown = True
        return len(text)

    def flush(self) -> None:
        pass

    def __exit__(self, *exc: Any) -> None:
        self._stack.close()
        if self.enabled and self._shown:
            self._err.write("\n")
            self._err.flush()


class working:
    """One updating line on stderr, ``LABEL … 12 s``, while a long step runs (fits, discovery)
    whose library call reports no progress of its own. Only on a terminal and without
    ``--quiet``; the line is cleared at the end, so logs and pipes stay clean.
    """

    def __init__(self, label: str, *, enabled: bool = True):
        import sys

        from .logs import is_quiet

        self.label = label
        self.enabled = enabled and not is_quiet() and sys.stderr.isatty()

    def __enter__(self) -> working:
        if self.enabled:
            import sys
            import threading
            import time

            self._stop = threading.Event()
            t0 = time.perf_counter()

            def tick() -> None:
                while not self._stop.wait(1.0):
                    sys.stderr.write(f"\r{self.label} … {time.perf_counter() - t0:.0f} s ")
                    sys.stderr.flush()

            self._thread = threading.Thread(target=tick, daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.enabled:
            import sys

            self._stop.set()
            self._thread.join()
            sys.stderr.write("\r" + " " * (len(self.label) + 16) + "\r")
            sys.stderr.flush()


# --- the output tail ----------------------------------------------------------------------------





def emit(
    report: Mapping[str, Any],
    *,
    json_out: bool,
    table: Callable[[], None] | None = None,
    out: Path | None = None,
    force: bool = False,
    files: Mapping[str, Any] | Callable[[], Mapping[str, Any]] | None = None,
    inputs: Iterable[Path | None] = (),
    gearbox: Gearbox | None = None,
    parameters: Mapping[str, Any] | None = None,
    seed: int | None = None,
) -> Path | None:
    """The tail of every command: the table (or ``--json``), then the files in ``--out``.

    `files` maps a file name to what goes in it: a mapping (JSON), a matplotlib figure (PNG or
    the suffix's format), ``str``/``bytes``, a callable ``writer(tmp_path)``, or an object with
    ``write_into(folder, name)`` (arrays: :class:`dtwin.io.export.Columns`/``Grid`` write
    ``NAME.csv`` and ``.npz``; :class:`dtwin.report.html_report.HTMLReport` writes ``report.html``
    from the files before it); a callable
    giving that mapping defers building figures until they are needed. The files appear together with
    ``manifest.json``, or not at all (interrupt, failure: see :class:`dtwin.io.output.OutputFolder`).

    **Returns:** the folder written, or None.
    """
    import json as _json

    from ..io.output import to_jsonable

    if json_out:
        typer.echo(_json.dumps(to_jsonable(report), indent=2))
    elif table is not None:
        table()
    if out is None:
        return None
    written = write_outputs(out, force=force, files=files, inputs=inputs, gearbox=gearbox,
                            parameters=parameters, seed=seed)
    if not json_out:
        import logging

        logging.getLogger("dtwin").info("wrote %s: %s, manifest.json", written,
                                        ", ".join(_names(files)))
    return written


def _names(files: Any) -> list[str]:
    return list(files) if isinstance(files, Mapping) else ["results"]


def write_outputs(out: Path, *, force: bool = False,
                  files: Mapping[str, Any] | Callable[[], Mapping[str, Any]] | None = None,
                  inputs: Iterable[Path | None] = (), gearbox: Gearbox | None = None,
                  parameters: Mapping[str, Any] | None = None, seed: int | None = None) -> Path:
    """Write `files` (see :func:`emit`) into `out` through a staged output folder."""
    from ..io.output import OutputFolder

    ins = [Path(p) for p in inputs if p is not None]
    if gearbox is not None and gearbox.file is not None and gearbox.file not in ins:
        ins.append(gearbox.file)
    with OutputFolder(out, force=force, inputs=ins,
                      spec=gearbox.spec_dict() if gearbox is not None else None,
                      parameters=parameters, seed=seed, staged=True) as folder:
        items = files() if callable(files) else (files or {})
        for name, value in items.items():
            _write_one(folder, name, value)
    return folder.path


def _write_one(folder: Any, name: str, value: Any) -> None:
    if hasattr(value, "write_into"):  # dtwin.io.export.Columns/Grid, dtwin.report.html_report.HTMLReport
        value.write_into(folder, name)
    elif isinstance(value, (bytes, bytearray)):
        folder.write_bytes(name, bytes(value))
    elif isinstance(value, str):
        folder.write_text(name, value)
    elif hasattr(value, "savefig"):
        import matplotlib.pyplot as plt

        folder.savefig(name, value)
        plt.close(value)
    elif callable(value):
        folder.write_with(name, value)
    else:
        folder.write_json(name, value)


def console() -> Any:
    """A rich console for tables: wraps cells rather than cutting them, 120 columns when the
    output is not a terminal (a pipe or a file), the terminal's width otherwise."""
    import sys

    from rich.console import Console

    width = None if sys.stdout.isatty() else int(os.environ.get("COLUMNS", "120") or 120)
    return Console(width=width, soft_wrap=False)


def print_table(table: Any) -> None:
    """Print a rich table so that no cell is cut (columns fold instead of ellipsis)."""
    for col in table.columns:
        if col.overflow == "ellipsis":
            col.overflow = "fold"
    console().print(table)


__all__ = [
    "MAX_DISCARD_S", "MAX_DURATION_S", "MAX_SEED", "MAX_SOLVER_STEPS", "PRESETS", "Gearbox",
    "GIVEN_SPEED_TOLERANCE", "OptionError", "at_least", "band", "channel_option",
    "channel_token", "check_channel", "check_fit_memory", "check_speed_against_lines",
    "check_out", "choice", "console", "count", "emit", "existing_file", "finite", "f_sun_option",
    "force_option", "in_range", "input_speed_option", "json_option", "load_gearbox",
    "out_option", "positive", "preset_option", "print_table", "read_record",
    "sample_rate_option", "simulated_span", "solver_steps", "spec_option", "speed_hint",
    "starts_and_refine",
    "tacho_option", "tacho_reading", "whole_number", "write_outputs",
]
