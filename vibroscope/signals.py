"""The one in-memory container of uniformly sampled channels."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np

__all__ = ["Signals", "true_runs", "block_bounds"]


def true_runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Runs of True in a 1-D boolean array (present samples, missing samples, a fault's samples).

    Parameters
    ----------
    mask : array_like of bool, shape (n,)

    Returns
    -------
    starts, stops : ndarray of int, shape (n_runs,)
        Index of each run's first element and one past its last (``mask[a:b]`` is all True).

    Examples
    --------
    >>> true_runs(np.array([True, True, False, True]))
    (array([0, 3]), array([2, 4]))
    """
    d = np.diff(np.concatenate(([0], np.asarray(mask, bool).view(np.int8), [0])))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def block_bounds(block_samples: int, stop: int, *, start: int = 0) -> Iterator[tuple[int, int]]:
    """Consecutive sample ranges ``[a, b)`` of `block_samples` from `start` to `stop`, the last shorter.

    The one blocking law of a record, in memory (:func:`vibroscope.viewers.rerun_live.record_blocks`)
    or read from a log (:meth:`vibroscope.io.blocks.LogGrid.blocks`).

    Parameters
    ----------
    block_samples : int
        Samples per block (at least 1).
    stop : int
        End of the range (sample index, exclusive).
    start : int, optional
        First sample index (default 0).

    Yields
    ------
    (int, int)
        ``(a, min(a + block_samples, stop))`` for ``a = start, start + block_samples, ...``.

    Raises
    ------
    ValueError
        If `block_samples` is not positive.

    Examples
    --------
    >>> list(block_bounds(4, 10))
    [(0, 4), (4, 8), (8, 10)]
    """
    if block_samples < 1:
        raise ValueError(f"{block_samples=} must be at least 1")
    block_samples = int(block_samples)
    for a in range(int(start), int(stop), block_samples):
        yield a, min(a + block_samples, int(stop))


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a)
    if a.flags.writeable:
        a = a.view()
        a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False, kw_only=True)
class Signals:
    """Uniformly sampled channels on one time grid.

    Parameters
    ----------
    data : array_like, shape (n_channels, n_samples)
        Samples in the units given by `units` (SI: m/s^2, N, m, ...). A 1-D array is taken
        as one channel. Stored read-only as float64.
    fs : float
        Sampling frequency in Hz.
    channels : sequence of str
        One name per channel, usually the Foxglove-style message path it was read from
        (``/imu/wrist.linear_acceleration.z``).
    units : sequence of str, optional
        One unit string per channel (``"m/s^2"``, ``"N"``). Defaults to ``""`` each.
    t0 : float, optional
        Time of the first sample in s (for MCAP logs: the first header stamp, in s since the
        epoch).
    meta : mapping, optional
        Free-form provenance: source file, time-base report, resampling done, warnings.

    Raises
    ------
    TypeError
        If `data` is complex (never cut silently to its real part).
    ValueError
        If `fs` is not positive and finite, or the number of channel names or units does not
        match the number of rows of `data`, or names repeat.

    See Also
    --------
    vibroscope.read_mcap : Signals from an MCAP log.
    vibroscope.simulate : Signals from a model's simulation.
    vibroscope.welch : Power spectral densities of the channels.

    Examples
    --------
    >>> import numpy as np
    >>> s = Signals(data=np.zeros((2, 1000)), fs=1000.0, channels=["/a.x", "/a.y"])
    >>> s.n_channels, s.n_samples, s.duration
    (2, 1000, 1.0)
    """

    data: np.ndarray
    fs: float
    channels: tuple[str, ...]
    units: tuple[str, ...] = ()
    t0: float = 0.0
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        data = np.asarray(self.data)
        if np.iscomplexobj(data):
            raise TypeError(f"data must be real (got dtype {data.dtype}): store the real and imaginary "
                            f"parts as separate channels")
        data = np.asarray(data, dtype=float)
        if data.ndim == 1:
            data = data[np.newaxis, :]
        if data.ndim != 2:
            raise ValueError(f"data must be 2-D (n_channels, n_samples), got {data.shape=}")
        fs = float(self.fs)
        if not np.isfinite(fs) or fs <= 0:
            raise ValueError(f"{fs=} must be a positive finite sampling frequency in Hz")
        channels = tuple(str(c) for c in self.channels)
        if len(channels) != data.shape[0]:
            raise ValueError(f"{len(channels)=} channel names for {data.shape[0]} data rows")
        if len(set(channels)) != len(channels):
            raise ValueError(f"channel names repeat: {channels=}")
        units = tuple(str(u) for u in self.units) if self.units else ("",) * len(channels)
        if len(units) != len(channels):
            raise ValueError(f"{len(units)=} units for {len(channels)} channels")
        object.__setattr__(self, "data", _readonly(data))
        object.__setattr__(self, "fs", fs)
        object.__setattr__(self, "channels", channels)
        object.__setattr__(self, "units", units)
        object.__setattr__(self, "t0", float(self.t0))
        object.__setattr__(self, "meta", dict(self.meta))

    # -- shape -----------------------------------------------------------------------------
    @property
    def n_channels(self) -> int:
        """Number of channels."""
        return self.data.shape[0]

    @property
    def n_samples(self) -> int:
        """Number of samples per channel."""
        return self.data.shape[1]

    @property
    def duration(self) -> float:
        """Record length ``n_samples / fs`` in s."""
        return self.n_samples / self.fs

    @property
    def time(self) -> np.ndarray:
        """Sample times in s, shape (n_samples,), starting at `t0`."""
        return self.t0 + np.arange(self.n_samples) / self.fs

    # -- selection -------------------------------------------------------------------------
    def index(self, channel: str | int) -> int:
        """Row index of `channel` (a name or an int).

        Parameters
        ----------
        channel : str or int
            A name of `channels`, or a row position (negative counts from the end).

        Returns
        -------
        int
            The non-negative row index.

        Raises
        ------
        KeyError
            If the name is not one of `channels`, or the position is out of range.
        """
        if isinstance(channel, (int, np.integer)):
            if not -self.n_channels <= channel < self.n_channels:
                raise KeyError(f"channel index {channel} out of range for {self.n_channels} channels")
            return int(channel) % self.n_channels
        try:
            return self.channels.index(channel)
        except ValueError:
            raise KeyError(f"no channel {channel!r}; channels are {list(self.channels)}") from None

    def __getitem__(self, channel: str | int) -> np.ndarray:
        """Samples of one channel, shape (n_samples,)."""
        return self.data[self.index(channel)]

    def select(self, channels: Iterable[str | int]) -> "Signals":
        """A new :class:`Signals` holding only `channels`, in that order.

        Parameters
        ----------
        channels : iterable of str or int
            Channel names or row positions (:meth:`index`).

        Returns
        -------
        Signals
            Same `fs`, `t0` and `meta`.

        Raises
        ------
        KeyError
            As :meth:`index`.
        """
        idx = [self.index(c) for c in channels]
        return Signals(
            data=self.data[idx],
            fs=self.fs,
            channels=[self.channels[i] for i in idx],
            units=[self.units[i] for i in idx],
            t0=self.t0,
            meta=self.meta,
        )

    def with_meta(self, **meta: Any) -> "Signals":
        """A copy with `meta` updated."""
        return Signals(data=self.data, fs=self.fs, channels=self.channels, units=self.units, t0=self.t0,
                       meta={**self.meta, **meta})

    @staticmethod
    def stack(parts: Sequence["Signals"]) -> "Signals":
        """Join channels of several Signals on the same grid (same fs and length).

        Parameters
        ----------
        parts : sequence of Signals
            The parts, their channels joined in order; `t0` is the first part's, the `meta`
            dicts are merged (later parts win).

        Returns
        -------
        Signals

        Raises
        ------
        ValueError
            If `parts` is empty, or the parts differ in `fs` or `n_samples`.
        """
        if not parts:
            raise ValueError("nothing to stack")
        fs, n = parts[0].fs, parts[0].n_samples
        for p in parts:
            if p.fs != fs or p.n_samples != n:
                raise ValueError(f"cannot stack {p.fs=} Hz x {p.n_samples=} with {fs=} Hz x {n=}")
        return Signals(
            data=np.vstack([p.data for p in parts]),
            fs=fs,
            channels=[c for p in parts for c in p.channels],
            units=[u for p in parts for u in p.units],
            t0=parts[0].t0,
            meta={k: v for p in parts for k, v in p.meta.items()},
        )

    def __repr__(self) -> str:
        return (
            f"Signals({self.n_channels} channels x {self.n_samples} samples, fs={self.fs:g} Hz, "
            f"t0={self.t0:g} s, channels={list(self.channels)[:4]}{'...' if self.n_channels > 4 else ''})"
        )
