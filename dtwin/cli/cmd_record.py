"""``dtwin record``: inspect recorded vibration files and convert them to dtwin's format.

    dtwin record info FILE [reading options] [--preset NAME | --spec FILE] [--f-sun HZ]
                           [--f-mesh HZ] [--f-carrier HZ] [--strict] [--json] [--out DIR]
    dtwin record convert FILE OUT.dtwin.h5 [reading options] [--force]

Reading options (see :func:`dtwin.io.readers.read_record`): ``--channels a,b,2`` (names,
indices or group names), ``--sample-rate HZ``, ``--time-column NAME``, ``--units g`` or
``--units acc=g,mic=Pa``, ``--sensitivity "acc=100 mV/g"`` (repeatable; ``"acc=100 mV/g ->
m/s^2"`` converts to m/s²), ``--tacho NAME``,
``--tacho-ppr N``, ``--tacho-shaft sun|carrier``, ``--group NAME``, ``--format FMT``.

``info`` prints a table of the channels (unit, min, max, RMS, problems), the rate, duration and
format, and every problem :func:`dtwin.io.validate.check_record` finds. The mesh and carrier
frequencies for the rate and duration checks come from ``--f-mesh``/``--f-carrier``, or from a
gearbox (``--preset``/``--spec``) at its operating speed (or ``--f-sun``). Exit code 0, or 2
with ``--strict`` when problems were found. ``--json`` prints the report on stdout; ``--out DIR``
writes ``record_info.json`` and ``manifest.json``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import typer

from ..errors import RecordError, SpecError
from ..report.analyses import record_report
from . import options as opts
from .app import app
from .logs import note

record_app = typer.Typer(help="Recorded vibration files (channels, rate, problems found; to *.dtwin.h5): info, convert.")
app.add_typer(record_app, name="record")

_SENS_RE = re.compile(r"^\s*(?P<ch>[^=]+?)\s*=\s*(?P<val>[-+0-9.eE]+)\s*(?P<unit>\S.*?)\s*$")


def _channel_token(tok: str) -> str | int:
    tok = tok.strip()
    return int(tok) if re.fullmatch(r"-?\d+", tok) else tok


def parse_channels(text: str | None) -> list[str | int] | None:
    """``"acc1,2,mic"`` → ``["acc1", 2, "mic"]`` (integers are indices)."""
    if text is None:
        return None
    items = [_channel_token(t) for t in text.split(",") if t.strip()]
    if not items:
        raise RecordError("--channels is empty; give names or indices separated by commas")
    return items


def parse_units(text: str | None) -> str | dict[str, str] | None:
    """``"g"`` (all channels) or ``"acc=g,mic=Pa"`` (per channel)."""
    if text is None or "=" not in text:
        return text
    out: dict[str, str] = {}
    for item in text.split(","):
        name, sep, unit = item.partition("=")
        if not sep or not name.strip():
            raise RecordError(f"--units item {item!r} not understood; write NAME=UNIT")
        out[name.strip()] = unit.strip()
    return out


def parse_sensitivity(items: list[str] | None) -> dict[str | int, tuple] | None:
    """``["acc=100 mV/g"]`` → ``{"acc": (100.0, "mV/g")}``; ``"acc=100 mV/g -> m/s^2"`` adds
    the output unit."""
    if not items:
        return None
    out: dict[str | int, tuple[float, str]] = {}
    for item in items:
        m = _SENS_RE.match(item)
        if not m:
            raise RecordError(f"--sensitivity {item!r} not understood; write e.g. "
                              "'acc=100 mV/g' or 'acc1=10.2 mV/(m/s^2)'")
        try:
            value = float(m.group("val"))
        except ValueError:
            raise RecordError(f"--sensitivity {item!r}: {m.group('val')!r} is not a number"
                              ) from None
        unit, arrow, target = m.group("unit").partition("->")
        out[_channel_token(m.group("ch"))] = ((value, unit.strip(), target.strip()) if arrow
                                              else (value, unit.strip()))
    return out


def _frequencies(gb: opts.Gearbox | None, f_sun: float | None,
                 f_mesh: float | None, f_carrier: float | None) -> dict[str, float]:
    freqs: dict[str, float] = {}
    if gb is not None:
        from ..model.gears import characteristic_frequencies

        spec_obj = gb.spec
        fs_in = f_sun if f_sun is not None else spec_obj["operating"].get("f_sun")
        if fs_in is None:
            raise SpecError([("operating.f_sun", "the spec states no input speed; pass --f-sun HZ")])
        freqs = {k: float(v) for k, v in
                 characteristic_frequencies(spec_obj.gear_set(), float(fs_in)).items()}
    elif f_sun is not None:
        raise opts.OptionError("--f-sun", "needs a gearbox: add --preset NAME or --spec FILE, or "
                               "give --f-mesh and --f-carrier directly")
    if f_mesh is not None:
        freqs["f_mesh"] = float(f_mesh)
    if f_carrier is not None:
        freqs["f_carrier"] = float(f_carrier)
    return freqs



def _read(file: Path, channels, sample_rate, time_column, units, sensitivity, tacho, tacho_ppr,
          tacho_shaft, group, fmt):
    from ..errors import ChannelError
    from ..io.readers import read_record

    try:
        return _read_record(read_record, file, channels, sample_rate, time_column, units,
                            sensitivity, tacho, tacho_ppr, tacho_shaft, group, fmt)
    except ChannelError as e:
        if tacho is not None and repr(_channel_token(tacho)) in str(e):
            raise ChannelError(f"--tacho: {e}") from None
        raise


def _read_record(read_record, file, channels, sample_rate, time_column, units, sensitivity,
                 tacho, tacho_ppr, tacho_shaft, group, fmt):
    return read_record(

        file, channels=parse_channels(channels), sample_rate=sample_rate,
        time_column=_channel_token(time_column) if time_column is not None else None,
        units=parse_units(units), sensitivity=parse_sensitivity(sensitivity),
        tacho=_channel_token(tacho) if tacho is not None else None, tacho_ppr=tacho_ppr,
        tacho_shaft=tacho_shaft, group=group, fmt=fmt)


_CHANNELS = typer.Option(None, "--channels", help="Channels to keep: names, indices or group "
                         "names, comma-separated.")
_RATE = typer.Option(None, "--sample-rate", help="Sampling rate (Hz) if the file states none.")
_TIME = typer.Option(None, "--time-column", help="Name (or index) of the time column (s).")
_UNITS = typer.Option(None, "--units", help="Unit for all channels ('g') or NAME=UNIT,...")
_SENS = typer.Option(None, "--sensitivity", help="Sensor sensitivity 'NAME=100 mV/g' "
                     "(repeatable); converts volts to the physical unit; 'NAME=100 mV/g -> "
                     "m/s^2' also converts the unit.")
_TACHO = typer.Option(None, "--tacho", help="Tachometer channel (name or index).")
_PPR = typer.Option(None, "--tacho-ppr", parser=opts.whole_number,
                    help="Tachometer pulses per revolution.")
_SHAFT = typer.Option(None, "--tacho-shaft", help="Shaft the tacho sees: sun or carrier.")
_GROUP = typer.Option(None, "--group", help="TDMS group, HDF5 group or MATLAB struct to read.")
_FMT = typer.Option(None, "--format", help="Force a format: csv wav numpy matlab hdf5 tdms uff "
                    "native.")


@record_app.command("info")
def info(
    file: Path = typer.Argument(..., help="Recorded vibration file."),
    channels: str | None = _CHANNELS,
    sample_rate: float | None = _RATE,
    time_column: str | None = _TIME,
    units: str | None = _UNITS,
    sensitivity: list[str] | None = _SENS,
    tacho: str | None = _TACHO,
    tacho_ppr: int | None = _PPR,
    tacho_shaft: str | None = _SHAFT,
    group: str | None = _GROUP,
    fmt: str | None = _FMT,
    preset: str | None = opts.preset_option("Gearbox for the mesh and carrier frequencies: "
                                            + ", ".join(opts.PRESETS) + "."),
    spec: Path | None = opts.spec_option(),

    f_sun: float | None = typer.Option(None, "--f-sun", help="Input (sun) speed (Hz), "
                                       "overriding the spec's operating point."),
    f_mesh: float | None = typer.Option(None, "--f-mesh", help="Mesh frequency (Hz)."),
    f_carrier: float | None = typer.Option(None, "--f-carrier", help="Carrier frequency (Hz)."),
    strict: bool = typer.Option(False, "--strict", help="Exit with code 2 if problems are found."),
    json_out: bool = typer.Option(False, "--json", help="Print the report as JSON on stdout."),
    out: Path | None = typer.Option(None, "--out", help="Write record_info.json and "
                                    "manifest.json into this folder."),
    force: bool = typer.Option(False, "--force", help="Overwrite results in --out."),
) -> None:
    """Channels, rate, duration and the problems found in a recorded vibration file."""
    from ..io.output import to_jsonable
    from ..io.validate import check_record

    _check_reading(sample_rate, units, tacho_ppr, tacho_shaft, fmt)
    opts.input_speed_option("--f-sun", f_sun)
    opts.positive("--f-mesh", f_mesh, unit="Hz")
    opts.positive("--f-carrier", f_carrier, unit="Hz")
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec, required=False)
    if gb is None and f_sun is not None:
        raise opts.OptionError("--f-sun", "needs a gearbox: add --preset NAME or --spec FILE, or "
                               "give --f-mesh and --f-carrier directly")
    freqs = _frequencies(gb, f_sun, f_mesh, f_carrier)
    opts.existing_file("FILE", file)
    rec = _read(file, channels, sample_rate, time_column, units, sensitivity, tacho, tacho_ppr,
                tacho_shaft, group, fmt)
    problems = check_record(rec, f_mesh=freqs.get("f_mesh"), f_carrier=freqs.get("f_carrier"))
    if gb is not None and f_mesh is None and not problems:
        problems += _speed_problems(rec, gb.spec, f_sun)
    with np.errstate(over="ignore"):  # an absurd sample (a problem above) overflows the RMS
        report = to_jsonable(record_report(rec, problems, freqs))
    opts.emit(report, json_out=json_out, table=lambda: _print_report(report), out=out,
              force=force, files={"record_info.json": report}, inputs=[file], gearbox=gb,
              parameters={"preset": preset, **freqs})
    if strict and problems:
        import sys

        kinds = sorted({p.kind for p in problems})
        print(f"error: {file}: {len(problems)} problem(s) found with --strict "
              f"({', '.join(kinds)}){'' if json_out else ', listed above'}", file=sys.stderr)
        raise SystemExit(2)


def _speed_problems(rec: Any, spec: Any, f_sun: float | None) -> list[Any]:
    """The speed the frequencies above come from (``--f-sun``, the tachometer, the record's
    metadata ``f_sun`` or the spec's ``operating.f_sun``), checked against the gear lines of the
    record's first channel (:func:`dtwin.identify.operating_point.check_speed`, as every
    command that analyses a record does): a speed the lines contradict, or lines absent where
    it puts them, is a problem of kind ``speed`` (issue 53: it passed silently)."""
    from dtwin.identify.operating_point import check_speed, resolve_speed

    from ..io.validate import Problem

    if rec.n_samples == 0 or not rec.channels:
        return []
    op = resolve_speed(rec, spec, f_sun, channel=0, estimate=False, check=False,
                       required=False)
    if op is None:
        return []
    what = {"given": "--f-sun", "tacho": "the tachometer's speed",
            "metadata": "the record's metadata f_sun", "spec": "the spec's operating.f_sun"
            }.get(op.method, "the speed")
    res = check_speed(rec, spec, op.f_sun, channel=0, what=what)
    if res.agrees:
        return []
    fix = ("correct --f-sun or drop it (the analyses then take the speed from the record)"
           if op.method == "given" else
           "pass the record's speed (--f-sun HZ) or check the spec's tooth numbers and the "
           "channel")
    return [Problem("speed", f"{res.message}; the frequencies above are at {op.f_sun:g} Hz: "
                             f"{fix}", rec.channels[0], None,
                    None if res.f_record is None else float(res.f_record))]


#: Units a record channel may be given in (``--units``): the vibration units of
#: :mod:`dtwin.signal.units`, volts, pressure, force and current.
KNOWN_UNITS = ("m/s^2", "mm/s^2", "g", "m/s", "mm/s", "in/s", "m", "mm", "um", "µm", "V", "mV",
               "Pa", "N", "A", "rad/s", "rpm", "-")


def _check_reading(sample_rate, units, tacho_ppr, tacho_shaft, fmt) -> None:
    """The reading options, checked before the file is opened."""
    from ..io.readers import EXTENSIONS, normalise_unit

    opts.positive("--sample-rate", sample_rate, unit="Hz")
    opts.at_least("--tacho-ppr", tacho_ppr, 1)
    opts.choice("--tacho-shaft", tacho_shaft, ("sun", "carrier"))
    opts.choice("--format", fmt, tuple(sorted(set(EXTENSIONS.values()))))
    parsed = parse_units(units)
    for u in ([parsed] if isinstance(parsed, str) else list((parsed or {}).values())):
        if normalise_unit(u) not in KNOWN_UNITS:
            raise opts.OptionError("--units", f"unknown unit {u!r}; use one of "
                                   f"{', '.join(KNOWN_UNITS)}")


@record_app.command("convert")
def convert(
    file: Path = typer.Argument(..., help="Recorded vibration file (any supported format)."),
    target: Path = typer.Argument(..., help="Output file, named *.dtwin.h5."),
    channels: str | None = _CHANNELS,
    sample_rate: float | None = _RATE,
    time_column: str | None = _TIME,
    units: str | None = _UNITS,
    sensitivity: list[str] | None = _SENS,
    tacho: str | None = _TACHO,
    tacho_ppr: int | None = _PPR,
    tacho_shaft: str | None = _SHAFT,
    group: str | None = _GROUP,
    fmt: str | None = _FMT,
    force: bool = typer.Option(False, "--force", help="Overwrite an existing output file."),
) -> None:
    """Convert a record to dtwin's own format (*.dtwin.h5), with units and sensitivity applied."""
    from ..errors import OutputExistsError
    from ..io.output import sha256_file
    from ..io.readers import write_record

    _check_reading(sample_rate, units, tacho_ppr, tacho_shaft, fmt)
    opts.existing_file("FILE", file)
    if not str(target).endswith(".dtwin.h5"):
        raise opts.OptionError("TARGET", f"name the output *.dtwin.h5, got {target}")
    if target.is_dir():
        raise opts.OptionError("TARGET", f"{target} is a folder; give a file name *.dtwin.h5")
    if _same_file(file, target):
        raise opts.OptionError("TARGET", f"{target} is the input file {file} itself (the same "
                               "file, perhaps through a link); converting would overwrite it: "
                               "give another output name")
    if target.exists() and not force:
        raise OutputExistsError(f"{target} already exists; pass --force to overwrite")
    opts.check_out(target.parent if str(target.parent) else Path("."), True, option="TARGET")
    rec = _read(file, channels, sample_rate, time_column, units, sensitivity, tacho, tacho_ppr,
                tacho_shaft, group, fmt)
    rec.metadata["source_sha256"] = sha256_file(file)
    path = write_record(rec, target, force=force)
    note(f"wrote {path}: {len(rec.channels)} channel(s), {rec.n_samples} samples at "
         f"{rec.sample_rate:g} Hz")



def _same_file(a: Path, b: Path) -> bool:
    """Whether `b` names the file `a` (the same path, another spelling of it, a symbolic or
    hard link to it, or a dangling link that resolves to it)."""
    try:
        if b.exists() and os.path.samefile(a, b):
            return True
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _print_report(report: dict[str, Any]) -> None:
    from rich.markup import escape
    from rich.table import Table

    console = opts.console()
    fr = report["frequencies_hz"]
    title = (f"{report['file']} ({report['format']}): {report['sample_rate_hz']:g} Hz, "
             f"{report['n_samples']} samples, {report['duration_s']:.4g} s")
    if "f_mesh" in fr:
        title += f", f_mesh = {fr['f_mesh']:.2f} Hz"
    table = Table(title=escape(title))
    for col in ("channel", "unit", "min", "max", "RMS", "problems"):
        table.add_column(col, justify="right" if col in ("min", "max", "RMS") else "left")

    def num(v: Any) -> str:
        return "-" if v is None or isinstance(v, str) else f"{v:.4g}"

    for c in report["channels"]:
        table.add_row(escape(c["name"]), escape(c["unit"] or "-"), num(c["min"]), num(c["max"]),
                      num(c["rms"]), ", ".join(c["problems"]) or "ok")
    opts.print_table(table)
    if report["tacho"]:
        t = report["tacho"]
        console.print(f"tacho: {escape(str(t['channel']))}, {t['ppr']} pulse(s)/rev, "
                      f"shaft {t['shaft']}")
    if report["groups"]:
        console.print("groups: " + escape(", ".join(f"{k} = {'/'.join(v)}"
                                                    for k, v in report["groups"].items())))
    if report["problems"]:
        console.print(f"[red]{len(report['problems'])} problem(s):[/red]")
        for p in report["problems"]:
            console.print(f"  - {escape(p['message'])}")
    else:
        console.print("[green]no problems found[/green]")
