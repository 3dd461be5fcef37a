"""Universal File Format (``.uff``/``.unv``) type-58 records via pyuff.

Each data set 58 with function type 1 (time response) and even abscissa spacing is one
channel: the rate is ``1 / abscissa_inc`` (s), the name is ``id1`` (or ``node<N><dir>`` from
the response node and direction when ``id1`` is empty or ``NONE``), the unit is the ordinate
axis unit label. All channels must share the increment and length.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import RecordError, UnreadableFileError
from .record import Record
from .values import as_signal, normalise_unit, resolve_rate

_DIRS = {1: "+x", 2: "+y", 3: "+z", -1: "-x", -2: "-y", -3: "-z", 0: ""}


def _name(ds: dict, i: int) -> str:
    id1 = str(ds.get("id1", "")).strip()
    if id1 and id1.upper() != "NONE":
        return id1
    node = ds.get("rsp_node")
    if node is not None:
        return f"node{int(node)}{_DIRS.get(int(ds.get('rsp_dir', 0)), '')}"
    return f"ch{i}"


def read(
    path: Path, *, sample_rate: float | None, time_column: str | int | None, group: str | None
) -> Record:
    """Read data sets 58 from a UFF file. **Returns:** one channel per time-response set."""
    import pyuff

    where = str(path)
    if group is not None or time_column is not None:
        raise RecordError(f"{where}: UFF files have no groups or time column; drop group= "
                          "and time_column=")
    try:
        uff = pyuff.UFF(str(path))
        types = list(np.asarray(uff.get_set_types()).astype(int).reshape(-1))
        idx = [i for i, t in enumerate(types) if t == 58]
        sets = uff.read_sets(idx) if idx else []
    except (ValueError, IndexError, KeyError, UnicodeError, OverflowError) as e:
        raise UnreadableFileError(f"{where}: not a readable UFF file ({type(e).__name__}: {e})"
                                  ) from None
    except Exception as e:  # pyuff reports every read failure as a plain Exception
        if type(e) is not Exception:
            raise
        raise UnreadableFileError(f"{where}: not a readable UFF file ({e})") from None
    if isinstance(sets, dict):
        sets = [sets]
    sets = [s for s in sets if s.get("type") == 58 and s.get("data") is not None]
    if not sets:
        raise UnreadableFileError(f"{where}: no UFF data set 58 (function at nodal DOF) found; "
                                  f"set types present: {sorted(set(types))}")
    time_sets = [s for s in sets if int(s.get("func_type", 1)) == 1]
    if not time_sets:
        raise RecordError(f"{where}: the data sets 58 are not time responses (function type "
                          f"{sorted({int(s.get('func_type', 0)) for s in sets})}); dtwin reads "
                          "time records (function type 1)")
    names, units, signals, incs = [], [], [], []
    for i, s in enumerate(time_sets):
        if int(s.get("abscissa_spacing", 1)) != 1:
            raise RecordError(f"{where}: data set {i} has uneven abscissa spacing; resample it "
                              "to a constant rate")
        data = np.asarray(s["data"])
        if np.iscomplexobj(data):
            raise RecordError(f"{where}: data set {i} is complex; time records are real")
        nm = _name(s, i)
        signals.append(as_signal(data, nm, where))
        names.append(nm)
        lab = normalise_unit(str(s.get("ordinate_axis_units_lab", "")))
        units.append("" if lab.upper() == "NONE" else lab)
        incs.append(float(s.get("abscissa_inc", 0.0)))
    if len(set(names)) != len(names):
        names = [f"{n}_{i}" for i, n in enumerate(names)]
    if len({s.size for s in signals}) > 1 or len(set(incs)) > 1:
        raise RecordError(f"{where}: UFF data sets differ in length or abscissa increment "
                          f"({[s.size for s in signals]}, {sorted(set(incs))} s); a record needs "
                          "one rate and length")
    if not incs[0] > 0:
        raise UnreadableFileError(f"{where}: abscissa increment {incs[0]} s is not positive")
    file_rate = 1.0 / incs[0]
    return Record(
        data=np.stack(signals),
        sample_rate=resolve_rate(file_rate, sample_rate, where),
        channels=tuple(names),
        units=tuple(units),
        metadata={"file_sample_rate": file_rate,
                  "uff_abscissa_min": float(time_sets[0].get("abscissa_min", 0.0))},
    )
