"""Reading MCAP logs into :class:`~vibroscope.signals.Signals`.

The log is scanned once into a :class:`~vibroscope.io.log_index.LogIndex` (chunk CRCs
checked, damage skipped and reported); each topic's fields are extracted by
:mod:`vibroscope.io._extract` (a numpy fast path over whole chunks for fixed-layout CDR
``sensor_msgs/msg/Imu`` and ``geometry_msgs/msg/WrenchStamped``, else the decoders of the
``mcap`` libraries: ROS 2 CDR, protobuf, JSON); outlier stamps are dropped, and the topics
are put on one grid by :mod:`vibroscope.io._grid`, which never interpolates across a gap.

Time base
---------
``header.stamp`` (sec + nanosec, int64 ns) where the message has a header, else the log
time (also when most header stamps are equal). Outlier stamps (more than 1000 periods and
1 s off their neighbours or their log time; a ``nanosec`` not below 1e9; a header stamp moved by
less, against both its log time and the stamps around it,
:func:`~vibroscope.io.timebase.outlier_stamps`) are dropped and reported; the rest are sorted, equal stamps dropped (first kept). A topic
whose stamps lie on the output grid within 1 % of a period is placed by index (no
interpolation; NaN where a message is missing; a few stamps off that grid, at most 1 %, are left
out as NaN); any other is interpolated (shape-preserving PCHIP, never outside its two neighbours,
after an anti-alias low-pass when its rate exceeds `fs` by 1 %,
:func:`~vibroscope.io.timebase.resample_to_grid`) within each run of stamps without a
missing message (:func:`~vibroscope.io.timebase.fit_stamps`: increments over 1.5 median
periods; for stamps with jitter, the rate is the slope of the stamps against the message count
and an increment is a gap only where a whole period is missing, not where the jitter of its
two stamps lengthens it), and is NaN in the gaps between runs and in lost chunks.

``Signals.meta`` of :func:`read_mcap`
-------------------------------------
``source`` (the file), ``t0_ns``; ``timebase`` (per topic a
:meth:`~vibroscope.io.timebase.TimebaseReport.as_dict`) and ``timebase_reports`` (the
objects); ``gaps`` (list of ``{"topic", "start_s", "length_s", "n_samples"}``: ``start_s``
absolute like ``t0``, ``n_samples`` the NaN grid samples); ``nan_samples`` (per channel);
``outliers`` (list of ``{"topic", "count", "stamps_ns", "log_times_ns"}``, at most 10 values
each); ``lost`` (per topic of the log ``{"messages", "seconds"}`` lost in damaged or missing
chunks, :meth:`~vibroscope.io._scan.ScanResult.lost_by_topic`; ``messages`` None when unknown); ``warnings`` (list of str, one line per problem); ``skipped`` (list of dicts: damage
with ``offset`` and ``reason``; undecodable topics with ``topic``, ``schema``, ``reason``;
bad messages with ``topic``, ``offset`` (of their chunk), ``field``, ``reason``);
``fast_path`` (per topic); ``indexed`` and ``chunks_skipped_by_index`` (the scan).
"""

from __future__ import annotations

import math
import numbers
from collections import defaultdict
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from vibroscope.errors import ChannelError
from vibroscope.io._extract import extract
from vibroscope.io._grid import TopicSamples, onto_grid
from vibroscope.io.log_index import (
    ACCELERATION_TYPES,
    LogIndex,
    LogInfo,
    TopicInfo,
    discover_fields,
    iter_raw_messages,
    mcap_info,
    select_acceleration_channels,
    unit_for,
)
from vibroscope.io.paths import MessagePath
from vibroscope.io._scan import memory_budget
from vibroscope.io.timebase import TimebaseReport, analyse_stamps, grid_for, outlier_stamps
from vibroscope.signals import Signals

__all__ = [
    "read_mcap",
    "mcap_info",
    "discover_fields",
    "select_acceleration_channels",
    "iter_raw_messages",
    "LogIndex",
    "LogInfo",
    "TopicInfo",
    "unit_for",
    "ACCELERATION_TYPES",
    "memory_budget",
    "check_read_args",
]


@dataclass
class ReadNotes:
    """What a read left out (``meta["skipped"]``), has to say (``meta["warnings"]``), dropped
    as outlier stamps (``meta["outliers"]``)."""

    skipped: list[dict]
    warnings: list[str]
    outliers: list[dict]
    lost: dict[str, dict]  # topic -> {"messages", "seconds"} lost in damaged or missing chunks

    @classmethod
    def of_scan(cls, log: LogIndex) -> "ReadNotes":
        """The damage the scan skipped, as skipped entries and warnings."""
        skipped = [{"offset": o, "reason": r} for o, r in log.scan.skipped]
        warnings = list(log.scan.warnings)
        warnings += [f"{log.path}: skipped at byte offset {o}: {r}" for o, r in log.scan.skipped]
        lost = {t: {"messages": k, "seconds": sec} for t, (k, sec) in sorted(log.scan.lost_by_topic().items())}
        return cls(skipped, warnings, [], lost)


def _wanted_topics(channels: Sequence[str] | None) -> set[str] | None:
    """Every prefix of the channels that could be the topic (matched exactly after the scan)."""
    if channels is None:
        return None
    return {c[:i] for c in channels for i in range(1, len(c) + 1) if i == len(c) or c[i] in ".["}


def _index_for(path: str | Path, channels: Sequence[str] | None, progress: bool,
               max_memory: int | None = None) -> LogIndex:
    """The log scanned for the topics of `channels` only (chunks of others passed over); scanned
    whole when that scan does not know a requested topic (channels only inside chunks)."""
    log = LogIndex.open(path, progress=progress, topics=_wanted_topics(channels), max_memory=max_memory)
    if channels is not None and log.scan.chunks_skipped_by_index:
        try:
            for c in channels:
                log.topic_of(c)
        except ChannelError:
            log = LogIndex.open(path, progress=progress, max_memory=max_memory)
    return log


def _imu_channels(log: LogIndex, notes: ReadNotes) -> list[str]:
    """The acceleration channels of every readable Imu topic; unreadable Imu topics noted.

    The first case of the commands' automatic choice (:func:`vibroscope.io.select.auto_channels`,
    :func:`vibroscope.io.log_index.select_acceleration_channels`), the only one a read with no
    channels makes: a log without an Imu topic is an error that lists its numeric fields."""
    sel, skip = select_acceleration_channels(log.info())
    for p, r in skip:
        if not r.startswith("not an IMU"):
            notes.skipped.append({"topic": p, "schema": "sensor_msgs/msg/Imu", "reason": r})
    if not sel:
        nums = log.discover_fields()
        hint = "; ".join(f"{t}: {len(v)} numeric fields, e.g. {v[:3]}" for t, v in list(nums.items())[:6])
        raise ChannelError(
            f"{log.path}: no acceleration field (no readable sensor_msgs/msg/Imu topic); choose channels "
            f"among the numeric fields (discover_fields): {hint}"
        )
    return sel


def usable_stamps(topic: str, stamps: np.ndarray, source: str, logt: np.ndarray, notes: ReadNotes):
    """(stamps, source): the log times instead of header stamps that are mostly equal, or whose
    clock steps back by more than 10 periods while the log times go on (a clock reset or a jump:
    sorting such stamps would interleave two stretches of the record)."""
    if source != "header.stamp" or stamps.size < 2:
        return stamps, source
    d = np.diff(stamps)
    if np.count_nonzero(d == 0) > 0.5 * (stamps.size - 1):
        notes.warnings.append(
            f"topic {topic!r}: header.stamp unusable (most consecutive stamps equal, e.g. {int(stamps[0])} ns, "
            f"in {stamps.size} messages); using log_time"
        )
        return logt, "log_time"
    if d.min() < 0:  # out of order somewhere: a step back of many periods is a clock, not jitter
        pos = d[d > 0]
        per = float(np.median(pos)) if pos.size else 0.0
        back = np.flatnonzero(d < -10 * per) if per > 0 else np.zeros(0, np.int64)
        lt = np.asarray(logt, np.int64)
        off = stamps - lt

        def lasting(k: int) -> bool:  # the stamp clock stays shifted against the log times (8+ messages on
            # each side): a reset, not one corrupted stamp (an outlier, dropped later) that comes back
            a, b = off[max(0, k - 63) : k + 1], off[k + 1 : k + 65]
            return a.size >= 8 and b.size >= 8 and abs(float(np.median(b)) - float(np.median(a))) > 10 * per

        back = np.array([k for k in back[:64] if lasting(int(k))], np.int64)
        if back.size and np.all(lt[back + 1] >= lt[back]):
            k = int(back[0])
            notes.warnings.append(
                f"topic {topic!r}: header.stamp steps back by {-d[k] * 1e-9:.6g} s after message {k + 1} (log time "
                f"{int(lt[k + 1])} ns){f' and {back.size - 1} more times' if back.size > 1 else ''} while the log "
                f"times go on: a clock reset or jump; using log_time")
            return logt, "log_time"
    return stamps, source


def drop_outliers(topic: str, stamps: np.ndarray, vals: np.ndarray, source: str, logt: np.ndarray,
                  notes: ReadNotes) -> tuple[np.ndarray, np.ndarray, int]:
    """Stamps, values without the outlier stamps (:func:`outlier_stamps`), reported; and their count."""
    bad = outlier_stamps(stamps, logt if source == "header.stamp" else None)
    nb = int(bad.sum())
    if not nb:
        return stamps, vals, 0
    st, lt = stamps[bad][:10].tolist(), logt[bad][:10].tolist()
    notes.outliers.append({"topic": topic, "count": nb, "stamps_ns": st, "log_times_ns": lt})
    notes.warnings.append(
        f"topic {topic!r}: {nb} outlier stamps dropped (far from their neighbours or their log time; "
        f"{source} {st}{' ...' if nb > 10 else ''} ns at log times {lt} ns)"
    )
    return stamps[~bad], vals[:, ~bad], nb


def read_topic(log: LogIndex, topic: str, fields: list[tuple[str | int, ...]], notes: ReadNotes, progress: bool,
               fast_path: dict[str, bool]) -> TopicSamples | None:
    """The requested fields of one topic with their time base, or None (noted) when unreadable;
    ``fast_path[topic]`` says whether the numpy fast path decoded it."""
    cids = log.by_topic[topic]
    cid = cids[0]
    dec, reason = log.decoders.get(log.scan.channels[cid], log.schema(cid))
    if dec is None:
        notes.skipped.append({"topic": topic, "schema": log.schema_name(cid), "reason": reason})
        notes.warnings.append(f"{log.path}: topic {topic!r} ({log.schema_name(cid)}) skipped: {reason}")
        return None
    if len(cids) > 1:
        notes.warnings.append(f"topic {topic!r} has {len(cids)} channels; reading channel id {cid} only")
    ex = extract(log, cid, fields, notes.skipped, notes.warnings, progress)
    fast_path[topic] = ex.fast
    stamps, source = usable_stamps(topic, ex.stamps, ex.source, ex.log_times, notes)
    stamps, vals, n_out = drop_outliers(topic, stamps, ex.values, source, ex.log_times, notes)
    # stamps are in file (logging) order: out-of-order counts refer to that order
    order, rep = analyse_stamps(topic, stamps, time_source=source, outliers=n_out)
    if stamps.size == 0:
        notes.skipped.append({"topic": topic, "schema": log.schema_name(cid), "reason": "no messages"})
        return None
    if rep.duplicates:
        notes.warnings.append(f"topic {topic!r}: {rep.duplicates} messages with duplicate stamps dropped")
    if rep.out_of_order:
        notes.warnings.append(f"topic {topic!r}: {rep.out_of_order} out-of-order stamps (sorted)")
    if order.size == stamps.size and not rep.out_of_order:  # increasing, no duplicate: order is the identity
        return TopicSamples(stamps, vals, rep)
    return TopicSamples(stamps[order], vals[:, order], rep)


def _drop_unmeasured_axes(by_topic: dict[str, list[int]], rows: dict[int, np.ndarray], parsed: list[MessagePath],
                          notes: ReadNotes) -> None:
    """Remove from `rows` an axis that is 0 in every message of a topic whose other axes move."""
    for topic, idxs in by_topic.items():
        zero = [i for i in idxs if i in rows and not np.any(rows[i])]
        if zero and len(zero) < len(idxs):
            for i in zero:
                del rows[i]
                notes.skipped.append({"topic": topic, "channel": str(parsed[i]),
                                      "reason": "identically zero in every message (axis not measured)"})


def _channels_read(log: LogIndex, parsed: list[MessagePath], rows: dict[int, np.ndarray],
                   notes: ReadNotes) -> list[int]:
    """Indices of the channels read; the others noted as not read. Raises when none was."""
    keep = [i for i in range(len(parsed)) if i in rows]
    if not keep:
        raise ChannelError(
            f"{log.path}: none of the requested channels can be read: "
            + "; ".join(f"{s.get('topic')}: {s['reason']}" for s in notes.skipped if "topic" in s)
        )
    for i in range(len(parsed)):
        if i not in rows and parsed[i].topic not in {s.get("topic") for s in notes.skipped}:
            notes.skipped.append({"topic": parsed[i].topic, "reason": "not read"})
    return keep


#: the highest output rate :func:`read_mcap` accepts, as a multiple of the highest estimated topic rate
MAX_UPSAMPLE = 100


def check_read_args(channels: Sequence[str] | None, fs: float | None = None, max_memory: int | None = None) -> None:
    """Refuse, before the log is read, a channel list given as one string and a rate or memory
    budget that is not a finite number > 0.

    Parameters
    ----------
    channels : sequence of str or None
        Message paths.
    fs : float, optional
        Rate in Hz.
    max_memory : int, optional
        Memory budget in bytes.

    Raises
    ------
    ValueError
        One line naming the argument and the limit.
    """
    if isinstance(channels, (str, bytes)):
        raise ValueError(f"channels={channels!r} must be a sequence of message paths, not one string "
                         f"(give [{channels!r}])")
    for name, v in (("fs", fs), ("max_memory", max_memory)):
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise ValueError(f"{name}={v!r} must be a number (Hz for fs, bytes for max_memory)")
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name}={v!r} must be finite and > 0")


def _check_grid(log: LogIndex, topics: list[str], samples: dict[str, TopicSamples], fs: float, n_rows: int,
                max_memory: int | None) -> None:
    """Refuse an output rate above :data:`MAX_UPSAMPLE` times the highest topic rate, and a
    grid whose rows need more than the memory budget, before the grid is allocated."""
    rates = [samples[t].report.fs_est for t in topics if np.isfinite(samples[t].report.fs_est)]
    top = max(rates, default=float("nan"))
    if np.isfinite(top) and fs > MAX_UPSAMPLE * top:
        raise ValueError(f"{fs=:g} Hz exceeds the limit of {MAX_UPSAMPLE} times the highest topic rate "
                         f"({top:.6g} Hz est.): {MAX_UPSAMPLE * top:.6g} Hz")
    _start, n = grid_for([(int(samples[t].t_ns[0]), int(samples[t].t_ns[-1])) for t in topics], fs)
    need = 2 * 8 * n * max(n_rows, 1)  # the rows on the grid and the stacked record, float64
    budget = memory_budget() if max_memory is None else int(max_memory)
    if need > budget:
        raise ValueError(f"{log.path}: the grid at {fs:g} Hz holds {n} samples x {n_rows} channels, about "
                         f"{need / 2**20:.0f} MiB, more than the memory budget of {budget / 2**20:.0f} MiB "
                         f"(max_memory; a lower fs, fewer channels or a larger budget)")


def _output_rate(log: LogIndex, fs: float | None, topics: list[str], reports: dict[str, TimebaseReport],
                 resample: bool) -> float:
    """`fs`, by default the highest estimated topic rate (the first topic's without resampling)."""
    if fs is None:
        cand = [reports[t].fs_est for t in topics if np.isfinite(reports[t].fs_est)]
        if not cand:
            raise ChannelError(f"{log.path}: cannot estimate a sample rate (fewer than 2 messages per topic)")
        fs = max(cand) if resample else cand[0]
    return float(fs)


def _as_logged(topics: list[str], samples: dict[str, TopicSamples], notes: ReadNotes) -> tuple[int, dict, dict]:
    """(start ns, rows per topic, resampled per topic) taken sample for sample (``resample=False``)."""
    lens = {t: samples[t].t_ns.size for t in topics}
    if len(set(lens.values())) != 1:
        raise ValueError(f"resample=False needs equal sample counts per topic, got {lens=}")
    for t in topics:
        rep = samples[t].report
        if rep.gaps:
            notes.warnings.append(
                f"topic {t!r}: {rep.gaps} gaps, {rep.gap_time_s:.4g} s missing in all (first at "
                f"{rep.gap_where_s[0][0]:.6g} s): samples taken as logged (resample=False), not on a uniform grid"
            )
    return int(samples[topics[0]].t_ns[0]), {t: samples[t].values for t in topics}, {t: False for t in topics}


def _topic_rows(log: LogIndex, by_topic: dict[str, list[int]], parsed: list[MessagePath], notes: ReadNotes,
                progress: bool, auto: bool):
    """(samples per topic, row per requested channel index, fast path per topic)."""
    samples: dict[str, TopicSamples] = {}
    fast_path: dict[str, bool] = {}
    rows: dict[int, np.ndarray] = {}
    for topic, idxs in by_topic.items():
        got = read_topic(log, topic, [parsed[i].fields for i in idxs], notes, progress, fast_path)
        if got is not None:
            samples[topic] = got
            rows.update({i: got.values[k] for k, i in enumerate(idxs)})
    if auto:  # an axis that is 0 in every message of a topic whose other axes move was not measured
        _drop_unmeasured_axes(by_topic, rows, parsed, notes)
    return samples, rows, fast_path


def _meta(log: LogIndex, notes: ReadNotes, reports: dict[str, TimebaseReport], resampled: dict[str, bool],
          fast_path: dict[str, bool], start: int, gaps: list[dict], names: list[str], data: np.ndarray) -> dict:
    """``Signals.meta`` of :func:`read_mcap` (keys in the module notes)."""
    return {
        "source": str(log.path),
        "timebase": {t: {**r.as_dict(), "resampled": resampled[t]} for t, r in reports.items()},
        "timebase_reports": {t: replace(r, resampled=resampled[t]) for t, r in reports.items()},
        "warnings": notes.warnings, "skipped": notes.skipped, "fast_path": fast_path, "t0_ns": int(start),
        "gaps": gaps, "nan_samples": {c: int(np.count_nonzero(np.isnan(r))) for c, r in zip(names, data)},
        "outliers": notes.outliers, "lost": notes.lost, "indexed": log.scan.indexed,
        "chunks_skipped_by_index": log.scan.chunks_skipped_by_index,
    }


def read_mcap(path: str | Path | LogIndex, channels: Sequence[str] | None = None, *, fs: float | None = None,
              progress: bool = False, resample: bool = True, max_memory: int | None = None) -> Signals:
    """Read channels of an MCAP log onto one uniform time grid.

    Parameters
    ----------
    path : str or Path or LogIndex
        The MCAP file (ROS 2 CDR, protobuf or JSON messages), or its index
        (:meth:`LogIndex.open`) when the caller scans it once for several uses.
    channels : sequence of str, optional
        Message paths, ``/topic.field.sub`` or ``/topic.array[i]``. Default: the
        ``linear_acceleration.{x,y,z}`` of every Imu topic (:func:`select_acceleration_channels`)
        less an axis that is 0 in every message while the others move (``meta["skipped"]``).
    fs : float, optional
        Output rate in Hz. Default: the highest estimated rate among the selected topics.
    progress : bool, optional
        Show a tqdm progress bar while scanning the file.
    resample : bool, optional
        If False, no grid: every topic must have the same number of samples (after
        dropping duplicate and outlier stamps), which are returned as they are at `fs`
        (default the first topic's estimated rate); gaps are reported, not filled.
    max_memory : int, optional
        Memory budget in bytes: no chunk whose stated uncompressed size exceeds its share is
        decompressed (:func:`vibroscope.io._scan.scan`), and a grid whose rows would need more
        is refused. Default :func:`vibroscope.io._scan.memory_budget` (half the available memory).

    Returns
    -------
    Signals
        ``data`` shape (n_channels, n_samples) in the fields' units (stored by the writer,
        else by the field name, :func:`unit_for`), NaN where nothing was logged (gaps and
        lost chunks are never interpolated; see the module notes on the time base);
        ``t0`` the first grid time in s; ``meta`` as in the module notes.

    Raises
    ------
    LogFormatError
        If nothing of the file can be read (names file and byte offset).
    ChannelError
        If a channel names an unknown topic or field, or no requested channel can be read,
        or (automatic selection) the log has no acceleration field, or the grid would be
        more than 10 times larger than the messages read (damaged stamps).
    ValueError
        With ``resample=False``, if the topics' sample counts differ; if `channels` is one string;
        if `fs` or `max_memory` is not a finite number > 0; if `fs` exceeds :data:`MAX_UPSAMPLE`
        times the highest topic rate, or the grid would need more than `max_memory` (checked
        before it is allocated).

    See Also
    --------
    vibroscope.io.blocks.iter_blocks : The same grid in consecutive blocks, for logs larger than memory.
    vibroscope.io.blocks.open_grid : The grid of a log, read range by range.
    vibroscope.stream.accumulate_log : Spectral sums of a log in one streamed pass, without its grid.
    vibroscope.io.LogIndex : The scan of a log, kept for several reads.
    vibroscope.io.write_ros2_mcap : The writer (a Signals to a ROS 2 log).

    Examples
    --------
    A 5 Hz sine logged at 100 Hz as ROS 2 Imu messages, read back sample for sample:

    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> from vibroscope import Signals
    >>> from vibroscope.io import write_ros2_mcap
    >>> t = np.arange(500) / 100.0
    >>> sig = Signals(data=np.sin(2 * np.pi * 5.0 * t)[None], fs=100.0,
    ...               channels=["/imu.linear_acceleration.z"], units=["m/s^2"])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     back = read_mcap(write_ros2_mcap(pathlib.Path(d) / "run.mcap", sig))
    >>> back.channels, back.fs, back.data.shape, back.units
    (('/imu.linear_acceleration.z',), 100.0, (1, 500), ('m/s^2',))
    >>> float(np.max(np.abs(back.data - sig.data)))
    0.0
    """
    check_read_args(channels, fs, max_memory)
    log = path if isinstance(path, LogIndex) else _index_for(path, channels, progress, max_memory)
    notes = ReadNotes.of_scan(log)
    auto = channels is None
    parsed = [log.topic_of(c) for c in (_imu_channels(log, notes) if auto else channels)]
    by_topic: dict[str, list[int]] = defaultdict(list)
    for i, mp in enumerate(parsed):
        by_topic[mp.topic].append(i)
    samples, rows, fast_path = _topic_rows(log, by_topic, parsed, notes, progress, auto)
    keep = _channels_read(log, parsed, rows, notes)
    topics = list(dict.fromkeys(parsed[i].topic for i in keep))
    reports = {t: samples[t].report for t in topics}
    for t in topics:
        if t in notes.lost:
            k, sec = notes.lost[t]["messages"], notes.lost[t]["seconds"]
            notes.warnings.append(f"topic {t!r}: {'an unknown number of' if k is None else k} messages lost in "
                                  f"damaged or missing chunks (log time ranges of {sec:.6g} s)")
    fs = _output_rate(log, fs, topics, reports, resample)
    if resample:
        _check_grid(log, topics, samples, fs, len(keep), max_memory)
    start, trows, resampled, gaps = (onto_grid(log.path, topics, samples, fs, notes.warnings) if resample
                                     else (*_as_logged(topics, samples, notes), []))
    picks = [(parsed[i].topic, by_topic[parsed[i].topic].index(i)) for i in keep]
    one = trows[picks[0][0]] if picks else None
    if (one is not None and picks == [(picks[0][0], r) for r in range(len(one))]
            and one.dtype == np.float64 and one.flags.c_contiguous):
        data = one  # every row of one topic, in order: its grid block as it is (no copy of the record)
    else:
        data = np.vstack([trows[t][r] for t, r in picks])
    names = [str(parsed[i]) for i in keep]
    meta = _meta(log, notes, reports, resampled, fast_path, start, gaps, names, data)
    return Signals(data=data, fs=fs, channels=names, units=[log.unit(parsed[i]) for i in keep], t0=start * 1e-9,
                   meta=meta)
