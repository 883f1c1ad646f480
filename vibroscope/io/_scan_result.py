"""What a scan of an MCAP file found: message :class:`Block` s, :class:`Damage` entries and the
:class:`ScanResult` that holds them (:func:`vibroscope.io._scan.scan` fills it)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.records import Channel, Header, Schema


class Block:
    """Messages found in one container (a chunk, or the loose messages of the data section).

    Parameters
    ----------
    buf : bytes-like or None
        The container's bytes (a decompressed chunk, or the file for loose messages); None
        when the scan dropped them after decoding the wanted fields (`reopen` gives them
        back on first use of :attr:`buf`).
    file_offset : int
        Byte offset of the chunk record (-1 for loose messages).
    channel_id : ndarray of uint16, shape (n,)
        Channel id of each message.
    log_time : ndarray of uint64, shape (n,)
        Log time of each message in ns.
    start : ndarray of int64, shape (n,)
        Payload offset of each message in :attr:`buf`.
    length : ndarray of int64, shape (n,)
        Payload length of each message in bytes.
    decoded : dict, optional
        Fields decoded by the scan's threads: channel id to (message type, stamps ns int64
        shape (k,), {field name: ndarray shape (k,)}) for the k messages of that channel in
        this block, in order.
    reopen : callable, optional
        Gives the chunk's bytes again (decompressed, size and CRC-32 checked) when `buf`
        is None.
    """

    __slots__ = ("_buf", "file_offset", "channel_id", "log_time", "start", "length", "decoded", "_reopen")

    def __init__(self, buf: Any, file_offset: int, channel_id: np.ndarray, log_time: np.ndarray, start: np.ndarray,
                 length: np.ndarray, decoded: dict | None = None, reopen: Any = None) -> None:
        if buf is None and reopen is None:
            raise ValueError("a block without its bytes needs `reopen`")
        self._buf = buf
        self.file_offset = file_offset
        self.channel_id = channel_id
        self.log_time = log_time
        self.start = start
        self.length = length
        self.decoded = decoded if decoded is not None else {}
        self._reopen = reopen

    @property
    def buf(self) -> Any:
        """The container's bytes (decompressed again, and kept, on first use when dropped).

        Raises
        ------
        LogFormatError
            If the chunk no longer decompresses to its size and CRC-32 (the file changed).
        """
        if self._buf is None:
            self._buf = self._reopen()
        return self._buf

    @property
    def n(self) -> int:
        """Number of messages."""
        return int(self.channel_id.size)

    def __repr__(self) -> str:
        return (f"Block(file_offset={self.file_offset}, n={self.n}, decoded={sorted(self.decoded)}, "
                f"bytes={'kept' if self._buf is not None else 'dropped'})")


@dataclass(frozen=True, kw_only=True)
class Damage:
    """One damaged place of a file and what was lost there.

    Parameters
    ----------
    offset : int
        Byte offset of the damaged record (or of the chunk lost).
    reason : str
        What was found there, and where the scan resumed.
    messages : int or None, optional
        Messages lost, when the message indexes (after the chunk, or listed by the summary)
        say so; None when unknown.
    channel_ids : tuple of int, optional
        Channels of the messages lost, when known.
    per_channel : tuple of (int, int), optional
        (channel id, messages lost) for each channel, when the message indexes say so.
    span_ns : (int, int) or None, optional
        First and last log time in ns of the messages lost (the lost chunk's time range, as its
        chunk index or its intact record header states it), when known.
    """

    offset: int
    reason: str
    messages: int | None = None
    channel_ids: tuple[int, ...] = ()
    per_channel: tuple[tuple[int, int], ...] = ()
    span_ns: tuple[int, int] | None = None

    def describe(self, channels: dict[int, Channel]) -> str:
        """The reason with the topics and message count lost (``"...; topics /a, /b (12 messages lost)"``)."""
        text = self.reason
        if self.channel_ids:
            topics = sorted({channels[c].topic for c in self.channel_ids if c in channels})
            unknown = [f"channel id {c}" for c in self.channel_ids if c not in channels]
            names = ([f"topic{'s' if len(topics) > 1 else ''} {', '.join(topics)}"] if topics else []) + unknown
            text += "; " + ", ".join(names)
        if self.messages is not None:
            text += f" ({self.messages} messages lost)"
        return text


@dataclass(kw_only=True)
class ScanResult:
    """What a scan found: schemas, channels, message blocks, and the damage.

    ``skipped`` lists (byte offset, reason) for every damaged place, in file order; a reason
    ends in ``"; topic /t (N messages lost)"`` when the loss is known (channel ids stand
    for topics no channel record names). ``damage`` holds the same as :class:`Damage`
    entries. ``warnings`` carries what cost no message (a damaged header, a chunk read
    through the summary's index, a summary not used, a data section CRC mismatch), each
    starting with the file's path. ``mode`` is the reading path asked for; ``indexed`` says
    whether a valid summary was used; ``recovered`` counts chunks read through the index
    despite a damaged record header.
    """

    path: Path
    file_size: int
    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    blocks: list[Block] = field(default_factory=list)
    skipped: list[tuple[int, str]] = field(default_factory=list)  # (byte offset, reason)
    warnings: list[str] = field(default_factory=list)
    complete: bool = False  # footer and closing magic seen
    indexed: bool = False  # a valid summary (chunk indexes) was used
    chunks_skipped_by_index: int = 0  # chunks not decompressed: none of the wanted topics in them
    mode: str = "auto"  # the reading path taken: "stream", "indexed" or "auto"
    damage: list[Damage] = field(default_factory=list)  # every damaged place, in file order
    recovered: int = 0  # chunks with a damaged record header read through the summary's index

    def lost_by_topic(self) -> dict[str, tuple[int | None, float]]:
        """Messages and seconds lost per topic, over every :attr:`damage` entry that says so.

        Returns
        -------
        dict of str to (int or None, float)
            Topic (``"channel id N"`` for a channel no record names) -> (messages lost, None
            when a damaged place lists the topic without a count for it; seconds covered by the
            log time ranges of the chunks lost that held it, overlaps counted once, 0.0 when no
            range is known).
        """
        count: dict[str, int | None] = {}
        spans: dict[str, list[tuple[int, int]]] = {}
        for d in self.damage:
            per = dict(d.per_channel)
            for c in d.channel_ids:
                name = self.channels[c].topic if c in self.channels else f"channel id {c}"
                k = per.get(c)
                if k is None and d.messages is not None and len(d.channel_ids) == 1:
                    k = d.messages
                prev = count.get(name, 0)
                count[name] = None if k is None or prev is None else prev + k
                if d.span_ns is not None:
                    spans.setdefault(name, []).append(d.span_ns)
        out = {}
        for name, k in count.items():
            sec, hi = 0, None
            for a, b in sorted(spans.get(name, [])):
                if hi is None or a > hi:
                    sec += b - a
                    hi = b
                elif b > hi:
                    sec += b - hi
                    hi = b
            out[name] = (k, sec * 1e-9)
        return out

    def messages(self) -> list[tuple[int, int, bytes]]:
        """Every message found, undecoded, blocks in order (chunks in file order, then the loose ones).

        Returns
        -------
        list of (int, int, bytes)
            (channel id, log time in ns, payload copied out).
        """
        out = []
        for b in self.blocks:
            mv = memoryview(b.buf)
            for c, t, s, n in zip(b.channel_id.tolist(), b.log_time.tolist(), b.start.tolist(), b.length.tolist()):
                out.append((c, t, bytes(mv[s : s + n])))
        return out


