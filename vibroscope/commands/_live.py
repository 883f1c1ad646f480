"""``vibroscope analyse LOG --connect``: a log read block by block and streamed to a running
rerun viewer through :class:`vibroscope.viewers.rerun_live.LiveView`.

This module does what the live view itself does not: it opens the log
(:func:`vibroscope.io.blocks.open_grid`: only the chunks that overlap each block are
decompressed), chooses the channels as ``analyse`` does
(:func:`vibroscope.io.select.auto_channels`), plans the segment length
(:func:`vibroscope.pipeline.default_nperseg` of the whole log) and connects to the viewer.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterable, Iterator, Literal, Sequence

import numpy as np

from vibroscope.signals import Signals
from vibroscope.viewers.rerun_live import LiveView, stream_blocks

__all__ = ["mcap_blocks", "stream_log", "DEFAULT_URL", "FLUSH_TIMEOUT_S"]

#: rerun's default gRPC proxy address (a viewer started with ``rerun`` listens there)
DEFAULT_URL = "rerun+http://127.0.0.1:9876/proxy"

#: most seconds :func:`stream_log` waits for the viewer to take the last data
FLUSH_TIMEOUT_S = 30.0


def mcap_blocks(path: str | Path, channels: Sequence[str] | None = None, *, fs: float | None = None,
                block_s: float = 1.0) -> Iterator[Signals]:
    """Blocks of `block_s` seconds of an MCAP log, for :class:`~vibroscope.viewers.rerun_live.LiveView`.

    The log is read block by block (:func:`vibroscope.io.blocks.open_grid`: only the chunks that
    overlap each block are decompressed), on one uniform grid for the whole log, so memory is
    bounded by the block, not the log; each block's ``meta["n_samples_total"]`` is the grid length.

    Parameters
    ----------
    path : str or Path
        The MCAP log.
    channels : sequence of str, optional
        Message paths (default: :func:`~vibroscope.io.read_mcap`'s, the Imu accelerations).
    fs : float, optional
        Rate to resample onto in Hz (default the highest topic rate).
    block_s : float, optional
        Block length in s (default 1.0).

    Yields
    ------
    Signals

    Raises
    ------
    ValueError
        If `block_s` is not positive.
    LogFormatError, ChannelError
        As :func:`vibroscope.io.blocks.open_grid`.
    """
    if not (np.isfinite(block_s) and block_s > 0):
        raise ValueError(f"{block_s=} must be a positive duration in s")
    from vibroscope.io.blocks import open_grid

    grid = open_grid(path, channels, fs=fs)
    for block in grid.blocks(max(1, int(round(block_s * grid.fs)))):
        block.meta["n_samples_total"] = grid.n_samples
        yield block


def stream_log(log: str | Path, *, url: str | None = None, input: str | None = None,
               outputs: Sequence[str] | None = None, fs: float | None = None, nperseg: int | None = None,
               estimator: Literal["H1", "H2", "Hv"] = "H1", block_s: float = 1.0,
               source: Callable[..., Iterable[Signals]] | None = None, rec=None) -> LiveView:
    """``vibroscope analyse LOG --connect [URL]``: stream a log to a running rerun viewer.

    Parameters
    ----------
    log : str or Path
        The MCAP log.
    url : str, optional
        The viewer's gRPC proxy (default :data:`DEFAULT_URL`, ``rerun+http://127.0.0.1:9876/proxy``).
    input : str, optional
        Force channel: the FRF from it to the outputs is streamed too.
    outputs : sequence of str, optional
        Response channels (default: chosen as ``analyse`` does,
        :func:`vibroscope.io.select.auto_channels`).
    fs : float, optional
        Rate in Hz to resample onto (default the highest topic rate).
    nperseg : int, optional
        Welch segment length (default :func:`vibroscope.pipeline.default_nperseg` of the log's
        length when the source knows it, else 4096).
    estimator : {'H1', 'H2', 'Hv'}, optional
        FRF estimator (default H1).
    block_s : float, optional
        Block length in s (default 1.0).
    source : callable, optional
        ``source(log, channels, fs=..., block_s=...)`` yielding the blocks (default
        :func:`mcap_blocks`).
    rec : rerun.RecordingStream, optional
        A recording with its sinks set (tests); default a new one connected to `url`.

    Returns
    -------
    LiveView
        Closed, after the final refresh; the recording is flushed and, when made here,
        disconnected.

    Raises
    ------
    ValueError
        If the log yields no sample, or as :class:`~vibroscope.viewers.rerun_live.LiveView`.
    ConnectionError
        If nothing listens at `url` (checked before the log is read).
    LogFormatError, ChannelError
        As :func:`vibroscope.io.read_mcap` (through the default source).

    Notes
    -----
    The address is checked (a TCP connection) before the log is read, since rerun's gRPC sink
    otherwise buffers silently and waits for a viewer; at the end the stream is flushed with a
    timeout of :data:`FLUSH_TIMEOUT_S` seconds, then disconnected.
    """
    import rerun as rr

    from vibroscope.io import LogIndex
    from vibroscope.io.select import auto_channels

    own = rec is None
    if own:  # before reading anything
        url = url or DEFAULT_URL
        _check_listening(url)
    if outputs is None:
        sel = auto_channels(LogIndex.open(log), exclude_topics=(input.split(".", 1)[0],) if input else ())
        outputs = [c for c in sel.channels if c != input]
    channels = [input, *outputs] if input else list(outputs)
    blocks = iter((source or mcap_blocks)(log, channels, fs=fs, block_s=block_s))
    first = next(blocks, None)
    if first is None:
        raise ValueError(f"{log}: no samples to stream")
    if nperseg is None:
        from vibroscope.pipeline import default_nperseg

        # the whole length when the source says it (meta), else a 4096-sample segment
        n = dict(first.meta or {}).get("n_samples_total")
        nperseg = default_nperseg(int(n), first.fs) if n else 4096
    if own:
        rec = rr.RecordingStream("vibroscope", recording_id=None)
        rec.send_recording_name(f"{Path(log).stem} (live)")
        rec.connect_grpc(url)
    try:
        view = stream_blocks(_chain(first, blocks), rec, input=input, nperseg=nperseg, estimator=estimator)
    finally:
        if own:
            rec.flush(timeout_sec=FLUSH_TIMEOUT_S)
            rec.disconnect()
    return view


def _check_listening(url: str, timeout_s: float = 2.0) -> None:
    """Raise ConnectionError naming `url` when nothing accepts a TCP connection at its host and port."""
    import socket
    from urllib.parse import urlparse

    u = urlparse(url)
    host, port = u.hostname or "127.0.0.1", u.port or 9876
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as exc:
        raise ConnectionError(f"no rerun viewer listening at {url} ({exc.strerror or exc}): start one with "
                              f"`rerun` (or `rerun --serve-grpc`), or give its address: --connect URL") from None


def _chain(first: Signals, rest: Iterator[Signals]) -> Iterator[Signals]:
    yield first
    yield from rest
