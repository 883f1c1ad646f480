"""Reading an MCAP log in time blocks on one fixed uniform grid, with memory bounded by the block.

:func:`open_grid` plans the reading once: the chunks of the log with their log-time spans (from the
summary's chunk indexes; a log without a usable summary is walked once record header by record
header, each chunk opened in turn to learn its channels and times, one at a time), the channels,
the grid rate `fs` and its origin ``t0_ns``. :meth:`LogGrid.read` then returns any stretch of grid
samples ``[i0, i1)`` as :class:`~vibroscope.signals.Signals`, decompressing only the chunks whose
log times can hold the stretch's messages, and :func:`iter_blocks` yields consecutive blocks.

The grid is on the header stamps, the chunk indexes on the log times, and the two clocks may differ
by far more than a block (a real log's joint states are stamped 46 s before they were logged). The
planning therefore learns, per topic, the range ``[lo, hi]`` of the offset ``stamp - log time`` over
the messages of the topic's first and last readable chunks (:attr:`LogGrid.stamp_offsets`); a block
whose stamps span ``[a, b]`` reads, per topic, the chunks of that topic whose log times overlap
``[a - hi, b - lo]`` widened by ``margin_s`` (jitter, and drift of the offset in the middle of the log
beyond what the end chunks show). Every block lies on the same grid, so blocks of
different time ranges line up exactly and their concatenation is one record.

Placement is that of :func:`~vibroscope.io.read_mcap` (:mod:`vibroscope.io._grid`): a topic whose
stamps lie on the grid is placed by index (no interpolation; NaN where nothing was logged, e.g. a
chunk lost to a CRC failure), so for such a topic the concatenated blocks equal ``read_mcap`` of the
whole log sample for sample when both use the same ``fs`` and origin. An off-grid topic is
interpolated within the block's stamps (those of the block's chunks, margin included): away from
the block edges and gaps it agrees with the whole-log read to the spline's accuracy, but not bit
for bit (the spline and any anti-alias filter see only the block's neighbourhood). Outlier and
duplicate stamps are dropped per block, and the on-grid decision is taken per block.

Memory: one block's grid ``(n_channels, block samples)`` plus the decompressed chunks overlapping it
(and its margin); never the whole file (the file is read with ``pread``, not mapped, so a log larger
than the address space can be read).
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from vibroscope.errors import ChannelError, LogFormatError
from vibroscope.io.timebase import round_rate
from vibroscope.signals import Signals, block_bounds

__all__ = ["ChunkSpan", "LogGrid", "open_grid", "iter_blocks"]

_MAGIC = b"\x89MCAP0\r\n"
_REC = struct.Struct("<BQ")
_CHUNK_OP, _SCHEMA_OP, _CHANNEL_OP, _FOOTER_OP, _DATA_END_OP = 0x06, 0x03, 0x04, 0x02, 0x0F


@dataclass(frozen=True)
class ChunkSpan:
    """One chunk of a log.

    Attributes
    ----------
    offset : int
        Byte offset of the chunk record.
    length : int
        Record length in bytes, opcode and length field included.
    start_ns, end_ns : int
        Earliest and latest message log time in the chunk, ns.
    channel_ids : frozenset of int or None
        Channels with messages in the chunk (None when unknown: then it is read for every topic).
    """

    offset: int
    length: int
    start_ns: int
    end_ns: int
    channel_ids: frozenset | None = None


def _pread(fd: int, n: int, offset: int) -> bytes:
    buf = os.pread(fd, n, offset)
    if len(buf) != n:
        raise ValueError(f"{n} bytes wanted at byte offset {offset}, {len(buf)} left in the file")
    return buf


def _open_chunk(fd: int, span: ChunkSpan):
    """(raw bytes, records, (cid, log time, start, length)) of one chunk, CRC checked; raises ValueError.

    The sizes the file states are checked before anything is allocated: the chunk must lie in the
    file, and its uncompressed size within the ratio limit and half the memory budget
    (:func:`vibroscope.io._scan.check_chunk_size`); decompression never goes beyond it."""
    from vibroscope.io import _scan
    from vibroscope.io._chunks import checked, read_chunk
    from vibroscope.io._index_kernels import index_messages

    size = os.fstat(fd).st_size
    if not (0 <= span.offset and 9 + 40 <= span.length and span.offset + span.length <= size):
        raise ValueError(f"chunk of {span.length} bytes at byte offset {span.offset} does not lie in the file "
                         f"({size} bytes)")
    rec = _pread(fd, span.length, span.offset)
    if rec[0] != _CHUNK_OP:
        raise ValueError(f"opcode 0x{rec[0]:02x} where a chunk record was expected")
    chunk = read_chunk(memoryview(rec), 9, len(rec))
    _scan.check_chunk_size(chunk, _scan.memory_budget() // 2)
    raw = checked(chunk)  # uncompressed: a view of `rec`, not a copy
    recs: list = []
    return raw, recs, index_messages(raw, 0, len(raw), recs, True)


def _summary_plan(path: Path, fh: Any, warnings: list[str] | None = None):
    """(schemas, channels, chunk spans, header, messages per channel id or None) from the summary
    section (the counts from its statistics record), or None without a usable one (none, a CRC-32
    mismatch that is not a deletion before it, a chunk index not pointing at a chunk record)."""
    from mcap.reader import SeekingReader

    from vibroscope.io._summary import locate_summary

    fd = fh.fileno()
    size = os.fstat(fd).st_size
    place, why = locate_summary(lambda off, k: _pread(fd, k, off), size)
    if place is None:
        return None
    if why is not None:  # bytes before the summary deleted (a lost chunk): found again, as the scan does
        return _relocated_plan(path, fh, size, warnings)
    try:
        rd = SeekingReader(fh)
        header = rd.get_header()
        summ = rd.get_summary()
    except Exception:  # noqa: BLE001 - a damaged or absent summary: the linear pass
        return None
    if summ is None or not summ.chunk_indexes:
        return None
    spans = [ChunkSpan(ci.chunk_start_offset, ci.chunk_length, ci.message_start_time, ci.message_end_time,
                       frozenset(ci.message_index_offsets) if ci.message_index_offsets else None)
             for ci in summ.chunk_indexes]
    if any(_pread(fd, 1, sp.offset)[0] != _CHUNK_OP for sp in spans):
        return None
    counts = dict(summ.statistics.channel_message_counts) if summ.statistics is not None else None
    return dict(summ.schemas), dict(summ.channels), sorted(spans, key=lambda s: s.offset), header, counts


def _relocated_plan(path: Path, fh: Any, size: int, warnings: list[str] | None):
    """The plan from a summary whose stated start is wrong because bytes before it were deleted
    (:func:`vibroscope.io._summary.read_summary` finds it again and places its chunk indexes on the
    chunk records where they now lie), or None. The chunks it lists that are not in the file are
    said in `warnings` (their messages are lost)."""
    import mmap

    from mcap.records import Header

    from vibroscope.io._records import REC_HDR, parse_record
    from vibroscope.io._summary import read_summary

    try:
        with mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            summ, _why = read_summary(mm, size)
            header = None
            if summ is not None and mm[8] == 0x01:
                _op, ln = REC_HDR.unpack_from(mm, 8)
                header = parse_record(Header, mm[8 + REC_HDR.size: 8 + REC_HDR.size + ln])
    except (ValueError, OSError):
        return None
    if summ is None or not summ.chunks:
        return None
    spans = [ChunkSpan(o, ci.chunk_length, ci.message_start_time, ci.message_end_time,
                       frozenset(ci.message_index_offsets) if ci.message_index_offsets else None)
             for o, ci in summ.chunks.items()]
    if warnings is not None:
        warnings.append(f"{path}: {summ.note or 'the summary found again after deleted bytes'}"
                        + ("; the messages of the missing chunks are lost" if summ.lost else ""))
    return dict(summ.schemas), dict(summ.channels), sorted(spans, key=lambda sp: sp.offset), header, None


def _linear_plan(path: Path, fd: int, size: int, warnings: list[str], skipped: list[tuple[int, str]]):
    """(schemas, channels, chunk spans, header, messages per channel id) by one pass over the record
    headers, each chunk opened in turn (one at a time) for its channels and times; the pass stops at
    damage (reported)."""
    from mcap.data_stream import ReadDataStream
    from mcap.records import Channel, Header, Schema
    from io import BytesIO

    schemas, channels, spans, header, counts = {}, {}, [], None, {}
    pos = 8
    while pos + 9 <= size:
        op, length = _REC.unpack(_pread(fd, 9, pos))
        end = pos + 9 + length
        if not (0x01 <= op <= 0x0F or op >= 0x80) or end > size:
            skipped.append((pos, f"damaged record (opcode 0x{op:02x}, length {length}): the blocks end here"))
            warnings.append(f"{path}: no usable summary and a damaged record at byte offset {pos}: streaming reads "
                            f"the log up to there only (read_mcap recovers after damage)")
            break
        if op in (_FOOTER_OP, _DATA_END_OP):
            break
        if op == _CHUNK_OP:
            span = ChunkSpan(pos, end - pos, 0, 0)
            try:
                _raw, recs, (cid, lt, _st, _ln) = _open_chunk(fd, span)
            except Exception as exc:  # noqa: BLE001 - the chunk is lost; its time span unknown
                skipped.append((pos, f"chunk skipped: {type(exc).__name__}: {exc}"))
            else:
                for r in recs:
                    (schemas if isinstance(r, Schema) else channels)[r.id] = r
                if cid.size:
                    ids, n = np.unique(cid, return_counts=True)
                    for c, k in zip(ids.tolist(), n.tolist()):
                        counts[c] = counts.get(c, 0) + k
                    spans.append(ChunkSpan(pos, end - pos, int(lt.min()), int(lt.max()), frozenset(ids.tolist())))
        elif op in (_SCHEMA_OP, _CHANNEL_OP, 0x01):
            body = _pread(fd, length, pos + 9)
            cls = {_SCHEMA_OP: Schema, _CHANNEL_OP: Channel, 0x01: Header}[op]
            try:
                r = cls.read(ReadDataStream(BytesIO(body)))
            except Exception:  # noqa: BLE001
                r = None
            if isinstance(r, Header):
                header = r
            elif r is not None:
                (schemas if op == _SCHEMA_OP else channels)[r.id] = r
        pos = end
    return schemas, channels, spans, header, counts


@dataclass(eq=False, kw_only=True)
class LogGrid:
    """A log planned for reading in blocks on one uniform grid (build with :func:`open_grid`).

    Attributes
    ----------
    path : Path
        The log.
    channels : tuple of str
        The message paths read, in row order.
    units : tuple of str
        Their units.
    fs : float
        Grid rate in Hz.
    t0_ns : int
        Time of grid sample 0 in ns (sample ``i`` is at ``t0_ns + round(i / fs * 1e9)``).
    n_samples : int
        Grid samples up to the end of the shortest topic.
    chunks : tuple of ChunkSpan
        The chunks, in file order.
    margin_s : float
        Chunks up to this much log time beyond a block's (offset-mapped) span are read too.
    indexed : bool
        Whether the summary's chunk indexes were used (else one linear pass).
    warnings : list of str
        What the planning noticed.
    skipped : list of (int, str)
        Damage found while planning: byte offset and reason.
    stamp_offsets : tuple of (str, int, int)
        Per topic read, ``(topic, lo_ns, hi_ns)``: the least and greatest ``stamp - log time``
        (ns) over the messages of its first and last readable chunks (0, 0 for a topic timed by
        its log times); a topic not listed is taken as (0, 0). Plain numbers: a Dask task of
        :mod:`vibroscope.fleet` carries them.
    """

    path: Path
    channels: tuple
    units: tuple
    fs: float
    t0_ns: int
    n_samples: int
    chunks: tuple
    margin_s: float
    indexed: bool
    warnings: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    _schemas: dict = field(default_factory=dict, repr=False)
    _channels: dict = field(default_factory=dict, repr=False)
    _header: Any = field(default=None, repr=False)
    _parsed: list = field(default_factory=list, repr=False)
    stamp_offsets: tuple = ()
    _chunk_times: Any = field(default=None, repr=False)
    _counts: Any = field(default=None, repr=False)  # messages per channel id (None: the summary has none)

    @property
    def duration(self) -> float:
        """Grid span ``n_samples / fs`` in s."""
        return self.n_samples / self.fs

    def time_of(self, i: int) -> int:
        """Time of grid sample `i` in ns.

        Parameters
        ----------
        i : int
            Grid index (may be negative or beyond the end).

        Returns
        -------
        int
        """
        return int(self.t0_ns + round(i / self.fs * 1e9))

    def index_of(self, t_s: float) -> int:
        """First grid index at or after the absolute time `t_s` (s, the clock of ``Signals.t0``).

        Parameters
        ----------
        t_s : float
            Time in s.

        Returns
        -------
        int
        """
        return int(np.ceil(round((t_s * 1e9 - self.t0_ns) * 1e-9 * self.fs, 6)))

    def force_input(self, *, exclude_channels: Sequence[str] = ()):
        """The log's one force-like channel that moves, as a whole read finds it
        (:func:`vibroscope.io.select.find_force_input`), looked for in the first and last chunks of
        each topic only (the log is not read whole), the topics' message counts from the summary.

        Parameters
        ----------
        exclude_channels : sequence of str, optional
            Message paths of the responses: their topics are never taken.

        Returns
        -------
        vibroscope.io.select.ForceInput
            Its ``channel`` is None when the log holds no force-like field that moves in those
            chunks, or several (``line()`` says which).
        """
        from vibroscope.io.select import find_force_input

        log, counts = _end_chunks(self)
        topics = {log.topic_of(c).topic for c in exclude_channels}
        return find_force_input(log, exclude_topics=topics, message_counts=counts)

    def _index(self, spans: Sequence[ChunkSpan], topics: set[str]):
        """A LogIndex over the chunks `spans` only (damaged ones skipped and reported)."""
        from vibroscope.io import _scan
        from vibroscope.io.log_index import LogIndex

        res = _scan.ScanResult(path=self.path, file_size=0, header=self._header, indexed=self.indexed)
        res.schemas.update(self._schemas)
        res.channels.update(self._channels)
        with open(self.path, "rb") as fh:
            fd = fh.fileno()
            for sp in spans:
                try:
                    raw, recs, (cid, lt, st, ln) = _open_chunk(fd, sp)
                except Exception as exc:  # noqa: BLE001 - the chunk is lost: its samples are NaN
                    res.skipped.append((sp.offset, f"chunk skipped: {type(exc).__name__}: {exc}"))
                    continue
                for r in recs:
                    (res.schemas if isinstance(r, _scan.Schema) else res.channels)[r.id] = r
                if cid.size:
                    res.blocks.append(_scan.Block(raw, sp.offset, cid, lt, st, ln))
        return LogIndex(res, topics)

    def _topic_cids(self, topic: str) -> set[int]:
        return {c for c, ch in self._channels.items() if ch.topic == topic}

    def _spans(self, a_ns: int, b_ns: int, topics: Sequence[str]) -> list[ChunkSpan]:
        """The chunks (file order) that can hold messages of `topics` stamped in ``[a_ns, b_ns]``: per
        topic, its chunks whose log times overlap ``[a_ns - hi, b_ns - lo]`` (its stamp offsets) widened
        by the margin."""
        if self._chunk_times is None:  # the chunks are fixed once planned
            self._chunk_times = (np.array([c.start_ns for c in self.chunks], np.int64),
                                 np.array([c.end_ns for c in self.chunks], np.int64), {})
        starts, ends, holds = self._chunk_times
        m = int(self.margin_s * 1e9)
        off = {t: (int(lo), int(hi)) for t, lo, hi in self.stamp_offsets}
        take = np.zeros(len(self.chunks), bool)
        for t in topics:
            if t not in holds:
                cids = self._topic_cids(t)
                holds[t] = np.array([c.channel_ids is None or bool(c.channel_ids & cids) for c in self.chunks], bool)
            lo, hi = off.get(t, (0, 0))
            take |= holds[t] & (ends >= a_ns - hi - m) & (starts <= b_ns - lo + m)
        return [c for c, k in zip(self.chunks, take) if k]

    def read(self, i0: int, i1: int) -> Signals:
        """Grid samples ``[i0, i1)`` of every channel.

        Parameters
        ----------
        i0, i1 : int
            Grid indices, ``i0 < i1`` (either may lie outside ``[0, n_samples)``: NaN there).

        Returns
        -------
        Signals
            ``data`` (n_channels, i1 - i0), NaN where nothing was logged (gaps, lost chunks);
            ``t0`` the time of sample `i0` in s; ``meta``: ``source``, ``t0_ns``, ``grid_index``
            (`i0`), ``warnings`` and ``skipped`` (chunks lost in this block, by byte offset).

        Raises
        ------
        ValueError
            If ``i1 <= i0``.
        """
        from vibroscope.io._grid import place_topic
        from vibroscope.io.mcap_read import ReadNotes, read_topic

        if i1 <= i0:
            raise ValueError(f"{i0=} must be less than {i1=}")
        n = i1 - i0
        by_topic: dict[str, list[int]] = {}
        for k, mp in enumerate(self._parsed):
            by_topic.setdefault(mp.topic, []).append(k)
        log = self._index(self._spans(self.time_of(i0), self.time_of(i1 - 1), list(by_topic)), set(by_topic))
        notes = ReadNotes.of_scan(log)
        data = np.full((len(self._parsed), n), np.nan)
        fast: dict[str, bool] = {}
        for topic, rows in by_topic.items():
            ids = log.by_topic.get(topic)
            if not ids or not log.count(ids[0]):
                continue  # nothing of this topic in the block's chunks: NaN
            got = read_topic(log, topic, [self._parsed[k].fields for k in rows], notes, False, fast)
            if got is None:
                continue
            out, _cov, _res = place_topic(got, self.t0_ns, n, self.fs, first=i0)
            data[rows] = out
        meta = {"source": str(self.path), "t0_ns": self.time_of(i0), "grid_index": int(i0),
                "warnings": notes.warnings, "skipped": notes.skipped}
        return Signals(data=data, fs=self.fs, channels=list(self.channels), units=list(self.units),
                       t0=self.time_of(i0) * 1e-9, meta=meta)

    def blocks(self, block_samples: int, *, start: int = 0, stop: int | None = None) -> Iterator[Signals]:
        """Consecutive blocks of `block_samples` grid samples from `start` to `stop` (the last shorter).

        Parameters
        ----------
        block_samples : int
            Samples per block (at least 1).
        start, stop : int, optional
            Grid indices; default the whole grid ``[0, n_samples)``.

        Yields
        ------
        Signals
            As :meth:`read`.

        Raises
        ------
        ValueError
            If `block_samples` is not positive.
        """
        for a, b in block_bounds(block_samples, self.n_samples if stop is None else stop, start=start):
            yield self.read(a, b)


def _first_last(grid: LogGrid, topic: str, cids: set[int], *,
                probe: bool = False) -> tuple[int, int, float, int, int, tuple]:
    """(first stamp, last stamp, estimated rate, least and greatest ``stamp - log time``, line) of a
    topic from its first and last readable chunks (all in ns but the rate, Hz); ``line`` is (the
    stamps (ns, increasing) of the first gap-free run of the first chunk; a list of runs of stamps
    further on, ending with the last run of the last chunk; the larger jitter of the stamps of the
    first and last chunks about their fitted lines in s, 0 when regular;
    :func:`~vibroscope.io.timebase.fit_stamps`). With `probe` and stamps with jitter, the list
    also holds the first runs of the topic's chunks 1, 2, 4, 8, ... (in increasing order): each
    of them at most twice as far from the first chunk as the one before, so that the count of
    periods to each is resolved by the rate refined on the one before.

    The stamps are taken as :func:`~vibroscope.io.read_mcap` takes them (header stamps, or the log
    times where the stamps are unusable; outlier stamps dropped), each paired with its message's log
    time by the extraction, which returns both in file order.
    """
    from vibroscope.io._extract import extract
    from vibroscope.io.mcap_read import drop_outliers, ReadNotes, usable_stamps
    from vibroscope.io.timebase import analyse_stamps, fit_stamps

    mine = [c for c in grid.chunks if c.channel_ids is None or c.channel_ids & cids]
    if not mine:
        raise ChannelError(f"{grid.path}: topic {topic!r} has no messages")
    mp = next(m for m in grid._parsed if m.topic == topic)

    def first_readable(spans):  # a lost chunk at either end: the next one inwards
        why = []
        for span in spans:
            log = grid._index([span], {topic})
            notes = ReadNotes.of_scan(log)
            ids = log.by_topic.get(topic)
            if ids:
                dec, reason = log.decoders.get(log.scan.channels[ids[0]], log.schema(ids[0]))
                if dec is None:  # the same decoder for every chunk: none of them reads
                    raise ChannelError(f"{grid.path}: topic {topic!r}: no chunk of it reads: "
                                       f"{log.schema_name(ids[0])}: {reason}")
                ex = extract(log, ids[0], [mp.fields], notes.skipped, notes.warnings, False)
                stamps, source = usable_stamps(topic, ex.stamps, ex.source, ex.log_times, notes)
                # the message indices ride along as the values: the kept stamps' own log times
                idx = np.arange(stamps.size, dtype=float)[None, :]
                stamps, idx, n_out = drop_outliers(topic, stamps, idx, source, ex.log_times, notes)
                if stamps.size:
                    order, rep = analyse_stamps(topic, stamps, time_source=source, outliers=n_out)
                    off = (stamps - ex.log_times[idx[0].astype(np.int64)] if source == "header.stamp"
                           else np.zeros(1, np.int64))  # timed by the log times: no offset
                    ts = stamps[order]
                    line = (ts, ts, 0.0)
                    if ts.size >= 2:  # the first and last gap-free runs of stamps, the jitter about their line
                        fit = fit_stamps(ts)
                        cut = np.flatnonzero(fit.gap)
                        first = ts[: cut[0] + 1] if cut.size else ts
                        last = ts[cut[-1] + 1 :] if cut.size else ts
                        line = (first, last, fit.jitter_s)
                    return (int(stamps.min()), int(stamps.max()), float(rep.fs_est), int(off.min()), int(off.max()),
                            line)
                why.append(f"chunk at byte offset {span.offset}: no usable stamp")
            why += notes.warnings[-1:]
        raise ChannelError(f"{grid.path}: topic {topic!r}: no chunk of it reads: " + "; ".join(why[:3]))

    a, b = first_readable(mine), first_readable(mine[::-1])
    jit = max(a[5][2], b[5][2])
    runs = []
    if probe and jit > 0:  # jittered stamps: chunks 1, 2, 4, 8, ... on the way to the last one
        i = 1
        while i < len(mine) - 1:
            try:
                runs.append(first_readable([mine[i]])[5][0])
            except ChannelError:  # a lost chunk: the next probe
                pass
            i *= 2
    line = (a[5][0], runs + [b[5][1]], jit)
    return a[0], b[1], a[2], min(a[3], b[3]), max(a[4], b[4]), line


def _refine_jittered(ta: np.ndarray, tb: np.ndarray, r: float, jit: float, *, snap: bool = True) -> float:
    """The rate `r` (Hz, from the first chunk) refined over the span of a topic whose stamps jitter.

    `ta` are the stamps (ns) of the first gap-free run of the first chunk, `tb` those of the last
    run of the last chunk. Each run's line at the refined period, ``mean(t_i - i T)``, places its
    first and last stamp to ``jit / sqrt(n)`` (a jittered stamp itself only to `jit`); the whole
    number of periods between them gives the rate, three times (the lines move with the period).
    With `snap`, the result is rounded within three standard errors of the span. A count off by one
    (the rate given wrong by half a period over the span) is not detected here: the caller refines
    over chunks ever further away (:func:`_first_last`).
    """
    rel_a = (ta - ta[0]).astype(np.float64) * 1e-9
    rel_b = (tb - ta[0]).astype(np.float64) * 1e-9  # both relative to one stamp: float64 keeps the ns
    for _ in range(3):
        T = 1.0 / r
        a0 = float(np.mean(rel_a - T * np.arange(rel_a.size)))
        b1 = float(np.mean(rel_b - T * np.arange(rel_b.size))) + T * (rel_b.size - 1)
        span = b1 - a0
        m = round(span * r)
        if m <= 0 or span <= 0:
            return r
        r = m / span
    return round_rate(r, 3.0 * jit * (1.0 / rel_a.size + 1.0 / rel_b.size) ** 0.5 / span) if snap else r


def _end_chunks(grid: LogGrid):
    """(LogIndex of the first and last chunks of every channel, messages per topic in the whole
    log: the summary's statistics, else the sampled chunks' counts scaled to all chunks)."""
    chans = grid._channels
    held = {cid: [c for c in grid.chunks if c.channel_ids is None or cid in c.channel_ids] for cid in chans}
    ends = {cid: {sp[0].offset: sp[0], sp[-1].offset: sp[-1]} for cid, sp in held.items() if sp}
    sample = sorted({o: c for e in ends.values() for o, c in e.items()}.values(), key=lambda c: c.offset)
    log = grid._index(sample, None)
    by_topic: dict[str, int] = {}
    for cid, ch in chans.items():
        if grid._counts is not None:
            n = int(grid._counts.get(cid, 0))
        else:  # no statistics: the sampled chunks' messages scaled to all chunks holding the channel
            n = round(log.log_times(cid).size * len(held.get(cid, ())) / max(1, len(ends.get(cid, ()))))
        by_topic[ch.topic] = by_topic.get(ch.topic, 0) + n
    return log, by_topic


def _automatic_channels(grid: LogGrid, exclude_topics: tuple) -> list[str]:
    """The channels of a log given none, chosen as the whole read chooses them
    (:func:`vibroscope.io.select.auto_channels`) without reading the whole log.

    1. ``linear_acceleration.{x,y,z}`` of every Imu topic (from the schemas alone).
    2. Else the measurement fields of the busiest decodable topic (messages × fields), the
       messages counted by the summary's statistics (else the chunks' own message indexes, or
       estimated from the sampled chunks), its fields found in its first message; of those, the
       fields that move within the first and last chunks of the topic, at most
       :data:`~vibroscope.io.select.MAX_AUTO_CHANNELS` in field order. Only those chunks (per
       channel) are decompressed: a field that moves only in the middle of the log is not chosen
       (the warning says so; name it with ``--outputs``).
    """
    from vibroscope.io._extract import extract
    from vibroscope.io.log_index import ACCELERATION_TYPES, acceleration_paths
    from vibroscope.io.select import MAX_AUTO_CHANNELS, auto_channels, moving_channels

    chans, schemas = grid._channels, grid._schemas
    imu = sorted({ch.topic for ch in chans.values() if ch.schema_id in schemas and ch.topic not in exclude_topics
                  and schemas[ch.schema_id].name in ACCELERATION_TYPES})
    if imu:
        return [c for t in imu for c in acceleration_paths(t)]
    log, by_topic = _end_chunks(grid)
    try:
        sel = auto_channels(log, message_counts=by_topic, exclude_topics=exclude_topics)
    except ChannelError as exc:
        raise ChannelError(f"{exc} (automatic choice from the summary and the first and last chunks)") from None
    topic = log.topic_of(sel.channels[0]).topic
    fields = [log.topic_of(c).fields for c in sel.channels]
    vals = np.concatenate([extract(log, cid, fields, [], [], False).values for cid in log.by_topic[topic]], axis=1)
    moving = moving_channels(sel.channels, vals)  # NaN marks a message without the field, not a value
    if not moving:
        raise ChannelError(f"{grid.path}: no Imu topic, and none of the {len(sel.channels)} measurement fields of "
                           f"{topic} moves in its first and last chunks; choose channels (vibroscope info lists "
                           f"the topics)")
    grid.warnings.append(
        f"channels chosen automatically: {sel.reason}: the {min(len(moving), MAX_AUTO_CHANNELS)} that move in "
        f"its first and last chunks" + (f" (the first {MAX_AUTO_CHANNELS} of {len(moving)})"
                                       if len(moving) > MAX_AUTO_CHANNELS else "")
        + f"; {len(sel.channels) - len(moving)} fields constant there not analysed")
    grid.warnings += [f"{what}: skipped: {why}" for what, why in sel.skipped]
    return moving[:MAX_AUTO_CHANNELS]


def _stamp_offsets(grid: LogGrid) -> tuple:
    """``(topic, lo_ns, hi_ns)`` per topic of the grid (:func:`_first_last`), without the rest."""
    out = []
    for t in dict.fromkeys(m.topic for m in grid._parsed):
        _a, _b, _r, lo, hi, _line = _first_last(grid, t, grid._topic_cids(t))
        out.append((t, lo, hi))
    return tuple(out)


def open_grid(path: str | Path, channels: Sequence[str] | None = None, *, fs: float | None = None,
              t0_ns: int | None = None, margin_s: float = 1.0, n_samples: int | None = None,
              stamp_offsets: Sequence[tuple[str, int, int]] | None = None,
              exclude_topics: Sequence[str] = ()) -> LogGrid:
    """Plan reading a log in blocks on one uniform grid.

    Parameters
    ----------
    path : str or Path
        The MCAP log.
    channels : sequence of str, optional
        Message paths. Default: ``linear_acceleration.{x,y,z}`` of every Imu topic (all three
        axes: an axis that never moves is not dropped here, unlike :func:`read_mcap`); in a log
        with no Imu topic, the measurement fields of the busiest topic that move, chosen from
        the summary and a few chunks (:func:`_automatic_channels`; the choice goes into
        :attr:`LogGrid.warnings`).
    fs : float, optional
        Grid rate in Hz. Default: the highest topic rate, estimated from the first chunk of
        each topic and refined over the whole span (the number of periods between the
        topic's first and last stamps), so that the grid holds over a long log. For stamps
        with jitter the first and last stamps are taken on the lines fitted to the first and
        last chunks (:func:`~vibroscope.io.timebase.fit_stamps`), the count of periods between
        them resolved over the topic's chunks 1, 2, 4, 8, ... (a few more chunks opened), and
        the rate is rounded within three standard errors of that span.
    t0_ns : int, optional
        Time of grid sample 0 in ns; default the latest first stamp of the topics (as
        :func:`read_mcap`).
    margin_s : float, optional
        Log time (s) read beyond each block's span, default 1 s. A block stamped ``[a, b]``
        reads, per topic, the chunks whose log times overlap ``[a - hi - margin_s, b - lo +
        margin_s]``, where ``[lo, hi]`` is the topic's range of ``stamp - log time`` seen in its
        first and last readable chunks (:attr:`LogGrid.stamp_offsets`): a constant offset of
        any size (stamps 46 s before their log times) costs nothing, and jitter or a drift of
        the offset in the middle of the log is covered up to `margin_s` beyond the range the end
        chunks show. That is the limit: where the offset wanders further than that inside the
        log, the messages stamped in a block may lie in chunks that are not read, and those
        samples come out NaN (:func:`~vibroscope.io.read_mcap` reads them); give a larger
        `margin_s` for such a log.
    n_samples : int, optional
        The grid's length when known (a Dask task of :mod:`vibroscope.fleet`): with `fs`,
        `t0_ns` and `stamp_offsets` also given, no chunk is opened to plan the grid (without
        `stamp_offsets`, the first and last chunks of each topic are opened for them).
        Default: to the end of the shortest topic.
    stamp_offsets : sequence of (str, int, int), optional
        ``(topic, lo_ns, hi_ns)`` per topic, as :attr:`LogGrid.stamp_offsets` of an earlier
        planning of the same log gives them; default learnt from the log.
    exclude_topics : sequence of str, optional
        Topics the automatic choice leaves out (the input's: a force is not a response).

    Returns
    -------
    LogGrid

    Raises
    ------
    LogFormatError
        If the file is not an MCAP log or holds no readable chunk.
    ChannelError
        If a channel names an unknown topic, a topic has no messages, or (automatic
        selection) the log has no Imu topic and no decodable topic with moving measurement
        fields.
    ValueError
        If `fs` or `margin_s` is not a positive (non-negative) finite number, or `channels` is
        one string (:func:`~vibroscope.io.mcap_read.check_read_args`).
    """
    from vibroscope.io.log_index import LogIndex

    from vibroscope.io.mcap_read import check_read_args

    path = Path(path)
    check_read_args(channels, fs)
    if not (np.isfinite(margin_s) and margin_s >= 0):
        raise ValueError(f"{margin_s=} must be a non-negative time in s")
    warnings: list[str] = []
    skipped: list[tuple[int, str]] = []
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read ({exc})") from exc
    with fh:
        size = os.fstat(fh.fileno()).st_size
        if size < 8 or _pread(fh.fileno(), 8, 0) != _MAGIC:
            raise LogFormatError(f"{path}: not an MCAP file (bad magic at byte offset 0)")
        plan = _summary_plan(path, fh, warnings)
        indexed = plan is not None
        if plan is None:
            warnings.append(f"{path}: no usable summary section: chunks located by one linear pass")
            plan = _linear_plan(path, fh.fileno(), size, warnings, skipped)
    schemas, chans, spans, header, counts = plan
    if not spans:
        raise LogFormatError(f"{path}: no readable chunk (streaming reads chunked logs)")
    grid = LogGrid(path=path, channels=(), units=(), fs=1.0, t0_ns=0, n_samples=0, chunks=tuple(spans),
                   margin_s=float(margin_s), indexed=indexed, warnings=warnings, skipped=skipped,
                   _schemas=schemas, _channels=chans, _header=header)
    grid._counts = counts
    probe = LogIndex(grid._index([], set()).scan)  # channels and schemas only: names and units
    if channels is None:
        channels = _automatic_channels(grid, tuple(exclude_topics))
    grid._parsed = [probe.topic_of(c) for c in channels]
    grid.channels = tuple(str(m) for m in grid._parsed)
    grid.units = tuple(probe.unit(m) for m in grid._parsed)
    if fs is not None and t0_ns is not None and n_samples is not None:
        grid.fs, grid.t0_ns, grid.n_samples = float(fs), int(t0_ns), int(n_samples)
        grid.stamp_offsets = (_stamp_offsets(grid) if stamp_offsets is None
                              else tuple((str(t), int(lo), int(hi)) for t, lo, hi in stamp_offsets))
        return grid
    topics = list(dict.fromkeys(m.topic for m in grid._parsed))
    firsts, lasts, rates, offsets = [], [], [], []
    for t in topics:
        a, b, r, lo, hi, (ta, runs, jit) = _first_last(grid, t, grid._topic_cids(t), probe=True)
        offsets.append((t, lo, hi))
        if np.isfinite(r) and r > 0 and b > a and jit > 0:
            for k, tb in enumerate(runs):  # chunks ever further, the last one last
                if tb[0] > ta[-1]:
                    r = _refine_jittered(ta, tb, r, jit, snap=k == len(runs) - 1)
        elif np.isfinite(r) and r > 0 and b > a:  # refine over the whole span: periods between first and last
            m = round((b - a) * 1e-9 * r)
            if m > 0 and abs(m / r - (b - a) * 1e-9) > 1e-9 * m ** 0.5:  # beyond the stamps' ns rounding
                r = m / ((b - a) * 1e-9)
        firsts.append(a), lasts.append(b), rates.append(r)
    if fs is None:
        good = [r for r in rates if np.isfinite(r)]
        if not good:
            raise ChannelError(f"{path}: cannot estimate a sample rate (fewer than 2 messages per topic)")
        fs = max(good)
    grid.fs = float(fs)
    grid.stamp_offsets = (tuple(offsets) if stamp_offsets is None
                          else tuple((str(t), int(lo), int(hi)) for t, lo, hi in stamp_offsets))
    grid.t0_ns = int(max(firsts)) if t0_ns is None else int(t0_ns)
    stop = min(lasts)
    grid.n_samples = max(0, int(np.floor((stop - grid.t0_ns) * 1e-9 * grid.fs + 1e-6)) + 1)
    return grid


def iter_blocks(path: str | Path, channels: Sequence[str] | None = None, *, fs: float | None = None,
                block_s: float = 10.0, time_range: tuple[float, float] | None = None,
                t0_ns: int | None = None) -> Iterator[Signals]:
    """Consecutive blocks of a log on one fixed uniform grid, each reading only its own chunks.

    Parameters
    ----------
    path : str or Path
        The MCAP log.
    channels : sequence of str, optional
        Message paths; default every Imu ``linear_acceleration.{x,y,z}`` (see :func:`open_grid`).
    fs : float, optional
        Grid rate in Hz; default the highest topic rate (see :func:`open_grid`).
    block_s : float, optional
        Block length in s (rounded to whole samples, at least one); default 10 s.
    time_range : (float, float), optional
        Absolute start and stop times in s (the clock of ``Signals.t0``); the grid samples
        ``t0 <= t < stop`` are read. Default: the whole grid.
    t0_ns : int, optional
        Grid origin in ns; default the latest first stamp of the topics.

    Yields
    ------
    Signals
        Shape (n_channels, samples of the block), NaN where nothing was logged, on the grid
        ``t0_ns + round(i / fs * 1e9)`` common to all blocks (``meta["grid_index"]`` is the index
        of the block's first sample); see :meth:`LogGrid.read`.

    Raises
    ------
    LogFormatError, ChannelError
        As :func:`open_grid`.
    ValueError
        If `block_s` is not positive, or `time_range` is empty.

    See Also
    --------
    vibroscope.io.read_mcap : The whole log on one grid, in memory.
    open_grid : The grid these blocks are cut from.

    Examples
    --------
    >>> for block in iter_blocks("run.mcap", block_s=60.0):  # doctest: +SKIP
    ...     acc.update(block.data)
    """
    if not (np.isfinite(block_s) and block_s > 0):
        raise ValueError(f"{block_s=} must be a positive duration in s")
    grid = open_grid(path, channels, fs=fs, t0_ns=t0_ns)
    start, stop = 0, grid.n_samples
    if time_range is not None:
        start, stop = grid.index_of(time_range[0]), grid.index_of(time_range[1])
        if stop <= start:
            raise ValueError(f"{time_range=} holds no grid sample")
    yield from grid.blocks(max(1, int(round(block_s * grid.fs))), start=start, stop=stop)
