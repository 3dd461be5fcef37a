"""Progress of the long commands on stderr, with an estimate of the time left.

``with progress("calibrate", json_out=json_out, size=...) as p:`` around a step that takes more
than a few seconds; ``p`` is a callable that takes one line of text per stage (pass it as the
library's ``progress``/``log`` callback). Each stage prints one line on stderr::

    calibrate [  12 s, about 70 s left]: final fit on all data

and on a terminal a spinner line below it keeps counting the seconds (rich). The estimate comes
from the last run of the same command on the same size of input (``size``: for example the
record's length and rate) on this machine, kept in ``dtwin-timings.json`` in the compilation
cache's folder (:mod:`dtwin._config`; no estimate when ``DTWIN_JAX_CACHE=off``): the time that
run took from its stage of the same number to its end. The first run shows the elapsed time
only. Nothing is printed under ``dtwin --quiet`` or ``--json``; stdout is never touched.
"""

from __future__ import annotations

import json
import os
import time
from typing import Any

#: Runs remembered per command and size (the newest are kept).
_KEEP = 64


def timings_file() -> str | None:
    """Where the stage times of earlier runs are kept (None: the compilation cache is off)."""
    from .._config import cache_dir

    folder = cache_dir()
    return None if folder is None else os.path.join(folder, "dtwin-timings.json")


def _load() -> dict[str, Any]:
    path = timings_file()
    try:
        with open(path) as f:  # type: ignore[arg-type]
            data = json.load(f)
        return data if isinstance(data, dict) else {}
    except (OSError, TypeError, ValueError):
        return {}


def _save(key: str, total: float, stages: list[float]) -> None:
    path = timings_file()
    if path is None:
        return
    data = _load()
    data.pop(key, None)
    data[key] = {"total": round(total, 2), "stages": [round(t, 2) for t in stages]}
    data = dict(list(data.items())[-_KEEP:])
    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        with open(tmp, "w") as f:
            json.dump(data, f)
        os.replace(tmp, path)
    except OSError:  # an unwritable cache folder: no estimate next time
        try:
            os.unlink(tmp)
        except OSError:
            pass


def estimate_left(last: dict[str, Any] | None, stage: int, elapsed: float) -> float | None:
    """Seconds left at the start of stage number `stage` (0 = the command's start), `elapsed`
    seconds in: the last run's time from its stage of that number to its end, or its total
    less `elapsed` when it had fewer stages; None without a last run or once past its end."""
    if not last:
        return None
    total = float(last["total"])
    stages = last.get("stages", [])
    if 0 < stage <= len(stages):
        left = total - float(stages[stage - 1])
    else:
        left = total - elapsed
    return left if left > 0 else None


class _Spinner:
    """The terminal's spinner line, its text formed anew at every refresh."""

    def __init__(self, owner: Progress):
        from rich.spinner import Spinner

        self.owner = owner
        self.spinner = Spinner("dots")

    def __rich__(self) -> Any:
        self.spinner.update(text=self.owner._status())
        return self.spinner


class Progress:
    """See the module docstring. `enabled` False: the stages are counted, nothing is shown."""

    def __init__(self, command: str, *, enabled: bool = True, size: str = ""):
        self.command = command
        self.enabled = enabled
        self.key = f"{command}|{size}"
        self.stages: list[float] = []
        self._live: Any = None

    def __enter__(self) -> Progress:
        self.t0 = time.perf_counter()
        self.last = _load().get(self.key) if self.enabled else None
        self.text = "starting"
        if self.enabled:
            from rich.console import Console

            self.console = Console(stderr=True, highlight=False, markup=False,
                                   soft_wrap=True)
            if self.console.is_terminal:  # a spinner line that counts the seconds
                from rich.live import Live

                self._live = Live(_Spinner(self), console=self.console, refresh_per_second=2,
                                  transient=True, redirect_stdout=False)
                self._live.start()
            self._print(self.text)
        return self

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def _status(self) -> str:
        elapsed = self.elapsed()
        left = estimate_left(self.last, len(self.stages), elapsed)
        est = "" if left is None else f", about {left:.0f} s left"
        return f"{self.command} [{elapsed:4.0f} s{est}]: {self.text}"

    def _print(self, text: str) -> None:
        self.text = text
        self.console.print(self._status())

    def __call__(self, message: str) -> None:
        """One stage: a line on stderr (when enabled)."""
        self.stages.append(self.elapsed())
        if self.enabled:
            self._print(" ".join(str(message).split()))

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        total = self.elapsed()
        if self._live is not None:
            self._live.stop()
        if exc_type is None:
            if self.enabled:
                self.text = "done"
                self.console.print(f"{self.command}: done in {total:.0f} s")
                _save(self.key, total, self.stages)


def progress(command: str, *, json_out: bool = False, size: str = "",
             enabled: bool = True) -> Progress:
    """A :class:`Progress` for `command`, silent under ``--quiet``, ``--json`` or when not
    `enabled` (a command's own ``--no-progress``)."""
    from .logs import is_quiet

    return Progress(command, enabled=enabled and not json_out and not is_quiet(), size=size)


def record_size(record: Any) -> str:
    """The size key of a record: its number of samples and rate (the estimate is per size)."""
    return f"{int(record.n_samples)}@{float(record.sample_rate):g}"


__all__ = ["Progress", "estimate_left", "progress", "record_size", "timings_file"]
