"""Result folders: atomic writes and a manifest of inputs, versions and parameters.

Every output of dtwin goes through :class:`OutputFolder`:

- files are written to a temporary name in the same folder, flushed, then renamed
  (``os.replace``), so a run that fails half-way leaves no partial file;
- an existing result file is never overwritten unless ``force=True``
  (:class:`~dtwin.errors.OutputExistsError` otherwise);
- ``manifest.json`` records the command line, the SHA-256 of every input file, the spec, the
  versions of dtwin and its main dependencies, the seed and any parameters, and lists the files
  written. It is rewritten (atomically) after each file, so it is always complete;
- a *staged* folder (``OutputFolder(..., staged=True)`` used as a context manager, as every
  command does) writes into a hidden ``.partial-*`` folder inside the result folder and moves
  the files in, the manifest last, only when the run has finished: an interrupted or failed
  run leaves no result file and no manifest, so the same command afterwards starts cleanly
  (the leftovers of an unfinished run are removed and may be overwritten without ``--force``).

Inputs are only ever opened for reading.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import shutil
import signal
import sys
import tempfile
import threading
from collections.abc import Iterable, Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

from ..errors import OutputExistsError, RecordError

# the file-level helpers live one level lower (dtwin.io.files: no import circle with the
# record writer); re-exported here, where callers have always found them
from .files import atomic_write_bytes as atomic_write_bytes
from .files import publish as publish
from .files import sha256_file as sha256_file
from .files import to_jsonable as to_jsonable
from .fmt_native import write_into

_MAIN_PACKAGES = (
    "dtwin", "jax", "jaxlib", "diffrax", "optimistix", "equinox", "lineax", "numpy", "scipy",
)


def versions() -> dict[str, str]:
    """Installed versions of dtwin and its main dependencies."""
    out = {"python": platform.python_version()}
    for name in _MAIN_PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


#: Staging folders of unfinished staged results, and a lock held while one is committed: a
#: process that must leave at once (:func:`discard_unfinished`) removes them, never half a move.
_STAGING: set[Path] = set()
_COMMIT_LOCK = threading.Lock()


def discard_unfinished() -> None:
    """Remove the staging folders of results not yet committed (waits for a commit under way).
    For an exit that cannot unwind normally (the CLI's hard exit on Ctrl-C)."""
    with _COMMIT_LOCK:
        for p in list(_STAGING):
            shutil.rmtree(p, ignore_errors=True)
            _STAGING.discard(p)


class _signals_deferred:
    """Hold SIGINT and SIGTERM back inside the block and deliver them after it (main thread)."""

    def __enter__(self) -> None:
        self._held: list[int] = []
        self._old: dict[int, Any] = {}
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old[sig] = signal.signal(sig, lambda s, f: self._held.append(s))

    def __exit__(self, *exc: Any) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        for sig in self._held[:1]:
            signal.raise_signal(sig)


class OutputFolder:
    """A folder of results written atomically, with a manifest.

    **Arguments:**

    - `path`: the folder (created if missing).
    - `force`: overwrite existing result files (otherwise `OutputExistsError`).
    - `command`: the command line (defaults to ``sys.argv``).
    - `inputs`: input files to hash into the manifest.
    - `spec`: the spec (a mapping) used.
    - `seed`: random seed, if any.
    - `parameters`: further parameters of the run.
    - `staged`: write into a hidden staging folder; :meth:`commit` (or leaving the ``with``
      block normally) moves the files in, the manifest last; :meth:`discard` (or leaving it by
      an exception, Ctrl-C included) removes them.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        force: bool = False,
        command: list[str] | None = None,
        inputs: Iterable[str | os.PathLike] = (),
        spec: Mapping[str, Any] | None = None,
        seed: int | None = None,
        parameters: Mapping[str, Any] | None = None,
        staged: bool = False,
    ):
        self.path = Path(path)
        self.force = force
        self.staged = staged
        self._final = self.path
        self.path.mkdir(parents=True, exist_ok=True)
        self.manifest: dict[str, Any] = {
            "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
            "command": list(sys.argv if command is None else command),
            "inputs": {},
            "spec": to_jsonable(spec) if spec is not None else None,
            "seed": seed,
            "parameters": to_jsonable(parameters or {}),
            "versions": versions(),
            "files": [],
        }
        for p in inputs:
            self.add_input(p)
        if (self.path / "manifest.json").exists() and not force:
            raise OutputExistsError(
                f"{self.path} already holds a result (manifest.json); choose another --out "
                "folder or pass --force to overwrite"
            )
        if staged:
            # no manifest: what lies here is left over from a run that never finished
            self._unfinished = not (self.path / "manifest.json").exists()
            for old in self.path.glob(".partial-*"):
                if old.is_dir():
                    shutil.rmtree(old, ignore_errors=True)
            self.path = Path(tempfile.mkdtemp(prefix=".partial-", dir=self._final))
            _STAGING.add(self.path)
            return
        self._write_manifest()

    def __enter__(self) -> OutputFolder:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()

    def commit(self) -> Path:
        """Move the staged files into the result folder, the manifest last (staged folders).

        Signals are held back while the files move, so Ctrl-C cannot split a result.
        **Returns:** the result folder.
        """
        if not self.staged or self.path == self._final:
            return self._final
        with _signals_deferred(), _COMMIT_LOCK:
            overwrite = self.force or self._unfinished
            for name in self.manifest["files"]:
                target = self._final / name
                if target.exists() and not overwrite:
                    self.discard()
                    raise OutputExistsError(f"{target} already exists; choose another output "
                                            "folder or pass --force to overwrite")
            _STAGING.discard(self.path)

            for name in self.manifest["files"]:
                os.replace(self.path / name, self._final / name)
            staging, self.path = self.path, self._final
            self._write_manifest()
            shutil.rmtree(staging, ignore_errors=True)
        return self._final

    def discard(self) -> None:
        """Remove the staged files (staged folders); the result folder stays as it was."""
        if self.staged and self.path != self._final:
            _STAGING.discard(self.path)
            shutil.rmtree(self.path, ignore_errors=True)

            self.path = self._final
            try:
                self._final.rmdir()  # only if it is empty (we may have created it)
            except OSError:
                pass

    def add_input(self, p: str | os.PathLike) -> None:
        p = Path(p)
        self.manifest["inputs"][str(p)] = {"sha256": sha256_file(p), "bytes": p.stat().st_size}

    def set(self, key: str, value: Any) -> None:
        """Record a further item in the manifest."""
        self.manifest[key] = to_jsonable(value)
        self._write_manifest()

    def _write_manifest(self) -> None:
        if self.staged and self.path != self._final:
            return  # written by commit(), after the files
        data = json.dumps(self.manifest, indent=2, sort_keys=False).encode()
        atomic_write_bytes(self.path / "manifest.json", data, force=True)

    def _register(self, name: str) -> Path:
        if name not in self.manifest["files"]:
            self.manifest["files"].append(name)
        self._write_manifest()
        return self.path / name

    def write_bytes(self, name: str, data: bytes) -> Path:
        atomic_write_bytes(self.path / name, data, force=self.force)
        return self._register(name)

    def write_text(self, name: str, text: str) -> Path:
        return self.write_bytes(name, text.encode())

    def write_json(self, name: str, obj: Any) -> Path:
        return self.write_bytes(name, json.dumps(to_jsonable(obj), indent=2).encode())

    def savefig(self, name: str, fig: Any, **kwargs: Any) -> Path:
        """Save a matplotlib figure atomically (PNG unless the name says otherwise)."""
        import io

        buf = io.BytesIO()
        fmt = Path(name).suffix.lstrip(".") or "png"
        kwargs.setdefault("dpi", 120)
        kwargs.setdefault("bbox_inches", "tight")
        fig.savefig(buf, format=fmt, **kwargs)
        return self.write_bytes(name, buf.getvalue())

    def write_with(self, name: str, writer: Any) -> Path:
        """Atomically write a file produced by ``writer(tmp_path)`` (for formats with own writers)."""
        target = self.path / name
        if target.exists() and not self.force:
            raise OutputExistsError(f"{target} already exists; pass --force to overwrite")
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix="-" + target.name, dir=self.path)
        os.close(fd)
        try:
            writer(tmp)
            publish(tmp, target)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
        return self._register(name)

    def write_record(self, name: str, record: Any) -> Path:
        """Write a :class:`~dtwin.io.record.Record` in dtwin's own format (``*.dtwin.h5``),
        atomically, and list it in the manifest (see :mod:`dtwin.io.fmt_native`)."""
        if not name.endswith(".dtwin.h5"):
            raise RecordError(f"record files are named '*.dtwin.h5', got {name!r}; rename it")
        return self.write_with(name, lambda tmp: write_into(record, tmp))
