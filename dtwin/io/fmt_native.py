"""dtwin's own record format: self-describing HDF5, ``*.dtwin.h5``.

Layout (format version 1):

- root attributes: ``dtwin_format = "dtwin-record"``, ``format_version`` (int),
  ``sample_rate`` (Hz), ``channels`` and ``units`` (JSON lists), ``groups`` (JSON object),
  ``metadata`` (JSON object), ``created_by`` (dtwin version);
- ``channels/000``, ``channels/001``, …: one float64 dataset per channel with attributes
  ``name`` and ``unit`` (numbered, so that any channel name is allowed);
- ``tacho`` (optional): float64 dataset with attributes ``ppr`` (pulses per revolution) and
  ``shaft`` (``sun``/``carrier``).

:func:`write` writes atomically: to a temporary file in the target folder, then ``os.replace``;
an existing file is never overwritten unless ``force=True``. ``dtwin simulate`` writes its
records with it; any HDF5 tool can read them.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ..errors import OutputExistsError, RecordError, UnreadableFileError
from .files import publish, to_jsonable
from .record import Record
from .values import resolve_rate, str_list, to_str

FORMAT_NAME = "dtwin-record"
FORMAT_VERSION = 1
_ERRORS = (OSError, KeyError, ValueError, RuntimeError, TypeError, IndexError)


def write_into(record: Record, path: str | os.PathLike) -> None:
    """Write `record` into a (new or truncated) HDF5 file at `path` (not atomic: see `write`)."""
    import h5py

    with h5py.File(path, "w") as f:
        f.attrs["dtwin_format"] = FORMAT_NAME
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["created_by"] = f"dtwin {__version__}"
        f.attrs["sample_rate"] = float(record.sample_rate)
        f.attrs["channels"] = json.dumps(list(record.channels))
        f.attrs["units"] = json.dumps(list(record.units))
        f.attrs["groups"] = json.dumps({k: list(v) for k, v in record.groups.items()})
        f.attrs["metadata"] = json.dumps(to_jsonable(record.metadata))
        grp = f.create_group("channels")
        for i, (name, unit) in enumerate(zip(record.channels, record.units, strict=True)):
            ds = grp.create_dataset(f"{i:03d}", data=np.asarray(record.data[i], np.float64))
            ds.attrs["name"] = name
            ds.attrs["unit"] = unit
        if record.tacho is not None:
            ds = f.create_dataset("tacho", data=np.asarray(record.tacho, np.float64))
            ds.attrs["ppr"] = -1 if record.tacho_ppr is None else int(record.tacho_ppr)
            ds.attrs["shaft"] = record.tacho_shaft or ""


def write(record: Record, path: str | os.PathLike, *, force: bool = False) -> Path:
    """Write `record` to `path` (``*.dtwin.h5``) atomically.

    **Arguments:** `record`; `path` (name it ``*.dtwin.h5`` so that :func:`read_record`
    recognises it by extension; any ``.h5`` name is recognised by its ``dtwin_format``
    attribute); `force`: overwrite an existing file (otherwise
    :class:`~dtwin.errors.OutputExistsError`).

    **Returns:** the path written.
    """
    path = Path(path)
    for kind, names in (("channel name", record.channels), ("unit", record.units)):
        for nm in names:
            if "\x00" in nm:
                raise RecordError(f"{kind} {nm!r} contains a NUL character, which HDF5 strings "
                                  "cannot hold; rename it")
    if path.exists() and not force:
        raise OutputExistsError(f"{path} already exists; choose another name or pass force=True "
                                "(CLI: --force) to overwrite")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        write_into(record, tmp)
        publish(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def _json_attr(attrs: Any, key: str, default: Any, where: str) -> Any:
    if key not in attrs:
        return default
    try:
        return json.loads(to_str(attrs[key]))
    except json.JSONDecodeError:
        raise UnreadableFileError(f"{where}: attribute {key!r} is not valid JSON") from None


def read(
    path: Path, *, sample_rate: float | None, time_column: str | int | None, group: str | None
) -> Record:
    """Read a ``*.dtwin.h5`` file. **Returns:** the record as written."""
    import h5py

    where = str(path)
    if group is not None or time_column is not None:
        raise RecordError(f"{where}: dtwin records have no groups or time column; drop group= "
                          "and time_column=")
    try:
        with h5py.File(path, "r") as f:
            if to_str(f.attrs.get("dtwin_format", "")) != FORMAT_NAME:
                raise UnreadableFileError(f"{where}: not a dtwin record (no dtwin_format "
                                          f"attribute {FORMAT_NAME!r}); read it as plain HDF5 "
                                          "with fmt='hdf5'")
            version = int(np.asarray(f.attrs.get("format_version", -1)).reshape(()))
            if version > FORMAT_VERSION:
                raise UnreadableFileError(f"{where}: dtwin record format {version} is newer "
                                          f"than this dtwin reads ({FORMAT_VERSION}); upgrade dtwin")
            file_rate = float(np.asarray(f.attrs["sample_rate"]).reshape(()))
            grp = f["channels"]
            keys = sorted(grp)
            names = [to_str(grp[k].attrs.get("name", k)) for k in keys]
            units = [to_str(grp[k].attrs.get("unit", "")) for k in keys]
            data = [np.asarray(grp[k][()], dtype=np.float64).reshape(-1) for k in keys]
            groups = _json_attr(f.attrs, "groups", {}, where)
            metadata = _json_attr(f.attrs, "metadata", {}, where)
            tacho = ppr = shaft = None
            if "tacho" in f:
                tacho = np.asarray(f["tacho"][()], dtype=np.float64).reshape(-1)
                ppr_v = int(np.asarray(f["tacho"].attrs.get("ppr", -1)).reshape(()))
                ppr = ppr_v if ppr_v > 0 else None
                shaft = to_str(f["tacho"].attrs.get("shaft", "")) or None
    except _ERRORS as e:
        if isinstance(e, RecordError):
            raise
        raise UnreadableFileError(f"{where}: damaged dtwin record ({type(e).__name__}: {e})"
                                  ) from None
    if len({d.size for d in data}) > 1:
        raise UnreadableFileError(f"{where}: channels of different lengths; the file is damaged")
    if not isinstance(groups, dict) or not isinstance(metadata, dict):
        raise UnreadableFileError(f"{where}: 'groups'/'metadata' attributes are not objects")
    n = data[0].size if data else 0
    if file_rate != sample_rate and sample_rate is not None:
        metadata["file_sample_rate"] = file_rate
    try:
        return Record(
            data=np.stack(data) if data else np.zeros((0, n)),
            sample_rate=resolve_rate(file_rate, sample_rate, where),
            channels=tuple(names),
            units=tuple(units),
            tacho=tacho,
            tacho_ppr=ppr,
            tacho_shaft=shaft,
            groups={str(k): tuple(str_list(v)) for k, v in groups.items()},
            metadata=metadata,
        )
    except ValueError as e:
        raise UnreadableFileError(f"{where}: inconsistent dtwin record ({e})") from None
