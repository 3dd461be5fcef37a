"""The in-memory vibration record every reader returns and every analysis takes."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..errors import ChannelError
from .files import to_jsonable


@dataclasses.dataclass(frozen=True)
class Record:
    """Sampled signals of one measurement (or one simulation).

    **Fields:**

    - `data`: float64 array, shape ``(n_channels, n_samples)``, in physical units (`units`).
    - `sample_rate`: sampling rate (Hz).
    - `channels`: channel names, one per row of `data`.
    - `units`: physical unit of each channel (e.g. ``m/s^2``, ``g``, ``V``).
    - `tacho`: optional tachometer signal (same rate and length as `data`), or None.
    - `tacho_ppr`: pulses per revolution of the tachometer (None without one).
    - `tacho_shaft`: which shaft the tachometer sees: ``"sun"`` (input), ``"carrier"`` (output).
    - `groups`: named channel groups, e.g. ``{"acc1": ("acc1_x", "acc1_y", "acc1_z")}`` for a
      triaxial accelerometer.
    - `metadata`: free-form (source file, machine, timestamp, sensitivity applied, spec, seed…).
    """

    data: np.ndarray
    sample_rate: float
    channels: tuple[str, ...]
    units: tuple[str, ...]
    tacho: np.ndarray | None = None
    tacho_ppr: int | None = None
    tacho_shaft: str | None = None
    groups: dict[str, tuple[str, ...]] = dataclasses.field(default_factory=dict)
    metadata: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        data = np.asarray(self.data, dtype=np.float64)
        if data.ndim == 1:
            data = data[None, :]
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "units", tuple(self.units))
        if len(self.channels) != data.shape[0] or len(self.units) != data.shape[0]:
            raise ValueError(
                f"record has {data.shape[0]} channels but {len(self.channels)} names and "
                f"{len(self.units)} units"
            )

    @property
    def n_samples(self) -> int:
        return int(self.data.shape[1])

    @property
    def duration(self) -> float:
        """Length of the record (s)."""
        return self.n_samples / float(self.sample_rate)

    @property
    def time(self) -> np.ndarray:
        """Sample times (s), starting at 0."""
        return np.arange(self.n_samples) / float(self.sample_rate)

    def index(self, channel: str | int) -> int:
        """Row of `channel` (a name or an index); unknown channels raise `ChannelError`."""
        if isinstance(channel, (int, np.integer)):
            if -len(self.channels) <= int(channel) < len(self.channels):
                return int(channel) % len(self.channels)
            raise ChannelError(
                f"channel index {channel} out of range: the record has {len(self.channels)} "
                f"channels {list(self.channels)}"
            )
        if channel in self.channels:
            return self.channels.index(channel)
        raise ChannelError(
            f"unknown channel {channel!r}; the record has {list(self.channels)}"
        )

    def channel(self, channel: str | int = 0) -> np.ndarray:
        """One channel's samples (a view, do not modify)."""
        return self.data[self.index(channel)]

    def select(self, channels: list[str | int] | tuple[str | int, ...]) -> Record:
        """A record with only the given channels (by name or index), in that order."""
        idx = [self.index(c) for c in channels]
        return dataclasses.replace(
            self,
            data=self.data[idx],
            channels=tuple(self.channels[i] for i in idx),
            units=tuple(self.units[i] for i in idx),
            groups={},
        )

    def to_xarray(self):
        """The record as an ``xarray.DataArray`` of dims ``("channel", "time")``: coordinates
        ``time`` (s) and ``channel`` (names), ``unit`` along ``channel``, the tachometer (if any)
        as coordinate ``tacho`` along ``time``; ``attrs`` hold the sampling rate, the tachometer's
        pulses per revolution and shaft, the groups and the JSON-able metadata. Needs xarray
        (``pip install xarray``, in the ``test`` extra)."""
        try:
            import xarray as xr
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("Record.to_xarray needs xarray: pip install xarray") from e
        coords: dict[str, Any] = {"time": ("time", self.time, {"units": "s"}),
                                  "channel": ("channel", list(self.channels)),
                                  "unit": ("channel", [u or "" for u in self.units])}
        if self.tacho is not None:
            coords["tacho"] = ("time", np.asarray(self.tacho, dtype=np.float64))
        attrs = {"sample_rate_hz": float(self.sample_rate),
                 "tacho_ppr": self.tacho_ppr if self.tacho_ppr is not None else "",
                 "tacho_shaft": self.tacho_shaft or "",
                 "groups": {k: list(v) for k, v in self.groups.items()},
                 "metadata": to_jsonable(self.metadata)}
        return xr.DataArray(self.data, dims=("channel", "time"), coords=coords, attrs=attrs,
                            name="vibration")

    def to_dataframe(self):
        """The record as a pandas DataFrame: index ``time`` (s), one column per channel (and
        ``tacho`` when present); units in ``df.attrs["units"]``, the sampling rate in
        ``df.attrs["sample_rate_hz"]``. Needs pandas (``pip install 'dtwin[fleet]'``)."""
        try:
            import pandas as pd
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("Record.to_dataframe needs pandas: pip install 'dtwin[fleet]'") from e
        cols = {c: self.data[i] for i, c in enumerate(self.channels)}
        if self.tacho is not None:
            cols["tacho"] = np.asarray(self.tacho, dtype=np.float64)
        df = pd.DataFrame(cols, index=pd.Index(self.time, name="time"))
        df.attrs["units"] = {c: u for c, u in zip(self.channels, self.units, strict=True)}
        df.attrs["sample_rate_hz"] = float(self.sample_rate)
        return df

    def channel_list(self, channel: str | int) -> list[int]:
        """Rows selected by a ``--channel`` token: ``"all"`` (every channel), a group name (a
        triaxial sensor's ``acc1`` → ``acc1_x, acc1_y, acc1_z``), a comma-separated list of
        names/indices, or one name/index."""
        if isinstance(channel, str):
            if channel == "all":
                return list(range(len(self.channels)))
            if channel in self.groups:
                return [self.index(c) for c in self.groups[channel]]
            if "," in channel:
                return [self.index(int(c) if c.strip().lstrip("-").isdigit() else c.strip())
                        for c in channel.split(",") if c.strip()]
        return [self.index(channel)]
