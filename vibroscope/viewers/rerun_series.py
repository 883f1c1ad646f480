"""Time series in a rerun recording: each channel on the ``time`` timeline, long channels as
their min/max envelope (true samples at their true times), gaps broken and listed.

rerun is imported inside the functions: importing this module never imports it.
"""

from __future__ import annotations

import numpy as np

from vibroscope.signals import true_runs
from vibroscope.viewers.rerun_paths import channel_entity

__all__ = ["envelope_indices", "log_time_series", "MAX_POINTS"]


#: most points logged per time-series channel: longer channels are logged as their min/max
#: envelope (:func:`envelope_indices`), 50 000 bins of two true samples each
MAX_POINTS = 100_000


def envelope_indices(x: np.ndarray, max_points: int | None = MAX_POINTS) -> np.ndarray:
    """Indices of the samples kept to draw `x` with at most `max_points` points: a min/max envelope.

    With ``n <= max_points`` finite samples, every finite sample is kept. Otherwise the record is
    cut into ``B = max_points // 2`` consecutive bins of ``w = ceil(n / B)`` samples and, in each
    bin, the sample of the smallest and the sample of the largest finite value are kept, in time
    order (one index when they coincide; none in a bin with no finite sample). Every kept point
    is a true sample at its true time, so each bin's extremes, and hence every peak and the
    record's minimum and maximum, are drawn exactly; only the path between extremes within a bin
    (``w`` samples, one pixel-like column of the plot) is left out. Missing samples (NaN, ±Inf)
    are never kept and never interpolated.

    Parameters
    ----------
    x : array_like, shape (n,)
        One channel.
    max_points : int or None, optional
        Most points kept (default :data:`MAX_POINTS`, 100 000); None keeps every finite sample.

    Returns
    -------
    ndarray of int64, shape (n_kept,)
        Ascending sample indices, ``n_kept <= max_points``.

    Raises
    ------
    ValueError
        If `max_points` is less than 2.
    """
    x = np.asarray(x, dtype=np.float64)
    present = np.isfinite(x)
    n = x.size
    if max_points is not None and max_points < 2:
        raise ValueError(f"{max_points=} must be at least 2 (a min and a max per bin), or None for every sample")
    if max_points is None or n <= max_points:
        return np.flatnonzero(present)
    n_bins = max_points // 2
    w = -(-n // n_bins)  # ceil
    n_bins = -(-n // w)
    clean = bool(present.all())
    if clean and n == n_bins * w:
        lo_src = hi_src = x
    else:  # missing samples never win; the last, partial bin padded with values that never win
        lo_src = np.full(n_bins * w, np.inf)
        hi_src = np.full(n_bins * w, -np.inf)
        lo_src[:n] = x if clean else np.where(present, x, np.inf)
        hi_src[:n] = x if clean else np.where(present, x, -np.inf)
    lo = lo_src.reshape(n_bins, w).argmin(axis=1)
    hi = hi_src.reshape(n_bins, w).argmax(axis=1)
    base = np.arange(n_bins, dtype=np.int64) * w
    idx = np.stack([base + np.minimum(lo, hi), base + np.maximum(lo, hi)], axis=1)
    if not clean:  # a bin with no finite sample keeps nothing (its argmin points at a missing sample)
        idx = idx[present[idx[:, 0]]]
    idx = idx.ravel()
    return idx[np.concatenate(([True], np.diff(idx) != 0))]  # one index where min and max coincide


def log_time_series(rec, prefix: str, sig, max_points: int | None = None) -> None:
    """Log every channel of `sig` under ``/<prefix>/<channel>`` on the ``time`` timeline (exact float64).

    A channel longer than `max_points` samples is logged as its min/max envelope
    (:func:`envelope_indices`): true samples at their true times, at most `max_points` of them;
    None logs every sample. One :meth:`~rerun.RecordingStream.send_columns` per channel.

    Missing samples (NaN, ±Inf) are not sent: the series is broken at each gap by a
    :class:`rerun.Clear` at the gap's first missing sample (scalar plots draw a clear as a hole,
    never a line across the gap), and each gap is a ``WARN`` entry of the :class:`rerun.TextLog`
    ``/<prefix>/gaps`` at its start time: ``"gap (no data) in <channel>: <start>–<stop> s
    (<n> samples)"``.

    Parameters
    ----------
    rec : rerun.RecordingStream
        The recording.
    prefix : str
        The first entity path part, e.g. ``"signals"``, ``"velocity"``.
    sig : Signals
        ``data`` (n_channels, n_samples), ``fs`` in Hz; times are s since the first sample.
    max_points : int or None, optional
        Most points per channel (:func:`envelope_indices`); None (default) logs every sample.
    """
    import rerun as rr

    for k, ch in enumerate(sig.channels):
        ent = channel_entity(prefix, ch)
        x = np.asarray(sig.data[k], dtype=np.float64)
        rec.log(ent, rr.SeriesLines(names=f"{ch} [{sig.units[k] or '-'}]"), static=True)
        keep = envelope_indices(x, max_points)
        t_ns = np.round(keep / sig.fs * 1e9).astype(np.int64).astype("timedelta64[ns]")  # rounded, not truncated
        rec.send_columns(ent, indexes=[rr.TimeColumn("time", duration=t_ns)],
                         columns=rr.Scalars.columns(scalars=x[keep]))
        if keep.size == x.size:
            continue
        present = np.isfinite(x)
        if present.all():
            continue
        starts, stops = true_runs(~present)
        log_ent = channel_entity(prefix, "gaps")
        for a, b in zip(starts, stops):
            rec.set_time("time", duration=np.timedelta64(int(np.round(a / sig.fs * 1e9)), "ns"))
            rec.log(ent, rr.Clear(recursive=False))
            rec.log(log_ent, rr.TextLog(f"gap (no data) in {ch}: {a / sig.fs:.6g}–{b / sig.fs:.6g} s ({b - a} samples)",
                                        level="WARN"))
        rec.reset_time()
