"""Streaming analysis of logs larger than memory: blocks of a log into the cross-spectral accumulator.

:func:`accumulate_log` reads a log block by block on one fixed grid (:mod:`vibroscope.io.blocks`)
into a :class:`~vibroscope.spectral._engine.CrossSpectralAccumulator`; memory is bounded by the
block, never by the log. A record split into grid-sample ranges at segment boundaries
(:func:`segment_ranges`: each range starts on a segment start and reads the ``nperseg - step``
samples of overlap with the next) gives accumulators whose :func:`merge_spectra` equals one pass
over the whole record — the exact decomposition used by :mod:`vibroscope.fleet` on Dask.

:func:`analyse_stream` then does, from the spectra alone, what
:func:`vibroscope.pipeline.analyse_signals` does from the time series where it can: PSDs, the
cross-spectral matrix, FRFs (H1/H2/Hv) with coherence, the band (the input's excited band, or the
responses' lowest resonance to their 95 % variance limit) and the modes — LSCF + LSFD on the FRFs
with an input, FDD/EFDD on the response CSD without (SSI-COV and polyMAX-OMA need the time series
and are not available here). No decimation (the record is never held whole): `fmax` limits the
band searched only. Each block's samples missing in one channel are set missing in all (every
spectral entry from the same segments, as ``analyse_signals`` does).
"""

from __future__ import annotations

import warnings as _warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from vibroscope.pipeline import Analysis
from vibroscope.signals import true_runs
from vibroscope.spectral import CrossSpectralAccumulator, CrossSpectralMatrix, frf, segment_settings

__all__ = ["LogSpectra", "StreamAnalysis", "segment_ranges", "accumulate_log", "merge_spectra", "analyse_stream",
           "stream_settings", "MAX_STREAM_NPERSEG"]

#: the automatic segment length of a streamed log is at most this (a long log gains averages, not lines)
MAX_STREAM_NPERSEG = 1 << 14

#: default grid samples per block: the block's decompressed chunks dominate the memory (an Imu
#: message is ~330 bytes: ~22 MB per Imu topic and block)
BLOCK_SAMPLES = 1 << 16

#: segments fed to the accumulator at a time (its FFT work space is this many segments per channel)
_PIECE_SEGMENTS = 4


def segment_ranges(n_samples: int, nperseg: int, noverlap: int, parts: int) -> list[tuple[int, int]]:
    """Grid-sample ranges holding whole Welch segments, for accumulating a record in `parts`.

    Parameters
    ----------
    n_samples : int
        Record length in samples.
    nperseg, noverlap : int
        Segment length and overlap in samples.
    parts : int
        Number of ranges wanted (fewer when the record has fewer segments).

    Returns
    -------
    list of (int, int)
        ``[i0, i1)`` per range: range k holds segments ``s0 .. s1 - 1`` and reads samples
        ``s0 step`` to ``(s1 - 1) step + nperseg`` (``step = nperseg - noverlap``), so consecutive
        ranges share ``noverlap`` samples and every segment of the whole record is in exactly one
        range. Empty when the record holds no segment.

    Raises
    ------
    ValueError
        If `parts` is not positive or ``noverlap`` is not in ``[0, nperseg)``.
    """
    if parts < 1:
        raise ValueError(f"{parts=} must be at least 1")
    if not 0 <= noverlap < nperseg:
        raise ValueError(f"{noverlap=} must be in [0, {nperseg=})")
    step = nperseg - noverlap
    n_seg = 0 if n_samples < nperseg else (n_samples - nperseg) // step + 1
    bounds = np.unique(np.linspace(0, n_seg, min(parts, max(n_seg, 1)) + 1).astype(int))
    return [(int(a) * step, (int(b) - 1) * step + nperseg) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def stream_settings(n_samples: int, fs: float, *, nperseg: int | None = None, noverlap: int | None = None,
                    window: Any = "hann", detrend: Any = "constant", nfft: int | None = None,
                    fmin: float | None = None) -> dict:
    """The Welch settings of a streamed record (the same for every range and every task).

    Parameters
    ----------
    n_samples : int
        Grid samples of the record.
    fs : float
        Grid rate in Hz.
    nperseg : int, optional
        Segment length; default :func:`vibroscope.pipeline.default_nperseg` (about 16 averages, fine
        enough for `fmin`), at most :data:`MAX_STREAM_NPERSEG`.
    noverlap : int, optional
        Overlap; default half a segment.
    window : str or tuple, optional
        Window (scipy's spec); default Hann.
    detrend : {'constant', 'linear', False}, optional
        Per-segment detrending; default 'constant'.
    nfft : int, optional
        FFT length; default `nperseg`.
    fmin : float, optional
        Lowest frequency of interest (Hz) for the automatic `nperseg`.

    Returns
    -------
    dict
        ``nperseg``, ``noverlap``, ``window``, ``detrend``, ``nfft`` (plain values, picklable).

    Raises
    ------
    ValueError
        If the settings are invalid for the record (:func:`segment_settings`).
    """
    from vibroscope.pipeline import default_nperseg

    if nperseg is None:
        nperseg = min(default_nperseg(max(n_samples, 16), fs, fmin=fmin), MAX_STREAM_NPERSEG)
    st = segment_settings(n_samples, nperseg=nperseg, noverlap=noverlap, window=window, detrend=detrend, nfft=nfft)
    return dict(nperseg=st.nperseg, noverlap=st.noverlap, window=window, detrend=detrend, nfft=st.nfft)


@dataclass(frozen=True, eq=False, kw_only=True)
class LogSpectra:
    """The cross-spectral sums of (a range of) a log, ready to merge or to scale.

    Attributes
    ----------
    sources : tuple of str
        The logs accumulated.
    channels, units : tuple of str
        Row names and units.
    fs : float
        Grid rate in Hz.
    samples : int
        Grid samples read (the overlaps of ranges of one log counted once).
    accumulator : CrossSpectralAccumulator
        The sums and per-pair segment counts (:attr:`~CrossSpectralAccumulator.n_averages`).
    settings : dict
        ``nperseg``, ``noverlap``, ``window``, ``detrend``, ``nfft``.
    warnings : tuple of str
        What the reading noticed (gaps, lost chunks), one line each.
    ranges : tuple of (str, int, int)
        (log, first grid index, stop index) of every range accumulated.
    t0_ns : int
        Grid origin of the first log in ns.
    gap_free : ndarray of int64, shape (k, 2), or None
        The stretches ``[a, b)`` (grid indices) of at least 16 samples with no channel missing,
        of one range read by :func:`accumulate_log` (with ``common_gaps``); None for merged
        spectra. They tell how many segments a shorter `nperseg` would fit between the gaps
        (:func:`analyse_stream` shortens the automatic one) without another pass.
    """

    sources: tuple
    channels: tuple
    units: tuple
    fs: float
    samples: int
    accumulator: Any
    settings: dict
    warnings: tuple = ()
    ranges: tuple = ()
    t0_ns: int = 0
    gap_free: Any = field(default=None, repr=False)

    def csd(self, scaling: str = "density") -> CrossSpectralMatrix:
        """The cross-spectral matrix (as :func:`~vibroscope.spectral.csd_matrix` gives it).

        Parameters
        ----------
        scaling : {'density', 'spectrum'}, optional
            unit²/Hz (default) or unit².

        Returns
        -------
        CrossSpectralMatrix

        Raises
        ------
        ValueError
            If no complete segment was accumulated, or a channel (pair) has no segment free of
            missing samples (names it).
        """
        from vibroscope.spectral.estimators import check_averages as _check_averages, settings_dict as _settings_dict

        acc = self.accumulator
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore")
            cnt = _check_averages(acc, self.channels, cross=True)
        sd = _settings_dict(self.fs, acc.settings, int(cnt.min()), acc.n_segments)
        return CrossSpectralMatrix(frequencies=acc.frequencies(), G=acc.result(scaling), channels=self.channels,
                                   units=self.units, scaling=scaling, settings=sd, n_averages=cnt)


def _new_accumulator(n_ch: int, fs: float, settings: dict) -> CrossSpectralAccumulator:
    st = segment_settings(None, nperseg=settings["nperseg"], noverlap=settings["noverlap"],
                          window=settings["window"], detrend=settings["detrend"], nfft=settings["nfft"])
    return CrossSpectralAccumulator(n_ch, fs, st, cross=True)


def accumulate_log(path: str | Path, channels: Sequence[str] | None = None, *, fs: float | None = None,
                   t0_ns: int | None = None, samples: tuple[int, int] | None = None,
                   time_range: tuple[float, float] | None = None, nperseg: int | None = None,
                   noverlap: int | None = None, window: Any = "hann", detrend: Any = "constant",
                   nfft: int | None = None, block_samples: int = BLOCK_SAMPLES, common_gaps: bool = True,
                   grid: Any = None, n_samples: int | None = None,
                   stamp_offsets: Sequence[tuple[str, int, int]] | None = None) -> LogSpectra:
    """Accumulate the cross-spectra of a log (or of a range of it) block by block.

    Parameters
    ----------
    path : str or Path
        The MCAP log.
    channels : sequence of str, optional
        Message paths; default every Imu ``linear_acceleration.{x,y,z}``.
    fs : float, optional
        Grid rate in Hz; default the highest topic rate (:func:`vibroscope.io.blocks.open_grid`).
    t0_ns : int, optional
        Grid origin in ns; default the latest first stamp of the topics.
    samples : (int, int), optional
        Grid-sample range ``[i0, i1)`` to accumulate (from :func:`segment_ranges` for an exact
        split); default the whole grid.
    time_range : (float, float), optional
        The same as absolute times in s (ignored when `samples` is given).
    nperseg, noverlap, window, detrend, nfft : optional
        Welch settings (:func:`stream_settings`; the automatic `nperseg` is taken from the whole
        grid's length, so every range of a log gets the same).
    block_samples : int, optional
        Grid samples read at a time (bounds the memory); default 2**16.
    common_gaps : bool, optional
        Set a sample missing in one channel missing in all (default), as
        :func:`~vibroscope.pipeline.analyse_signals` does.
    grid : LogGrid, optional
        The log already planned (:func:`~vibroscope.io.blocks.open_grid`); then `path`,
        `channels`, `fs`, `t0_ns`, `n_samples` and `stamp_offsets` are not used.
    n_samples : int, optional
        The whole grid's length when known (with `fs` and `t0_ns`: the log is planned without
        opening a chunk when `stamp_offsets` is given too, :func:`~vibroscope.io.blocks.open_grid`).
    stamp_offsets : sequence of (str, int, int), optional
        ``(topic, lo_ns, hi_ns)``: each topic's range of ``stamp - log time`` in ns, as
        :attr:`~vibroscope.io.blocks.LogGrid.stamp_offsets` of an earlier planning gives it (it
        chooses the chunks each block reads); default learnt from the log.

    Returns
    -------
    LogSpectra

    Raises
    ------
    LogFormatError, ChannelError
        As :func:`~vibroscope.io.blocks.open_grid`.
    ValueError
        If a setting is invalid, or the range is empty.
    """
    from vibroscope.io.blocks import open_grid

    g = grid if grid is not None else open_grid(path, channels, fs=fs, t0_ns=t0_ns, n_samples=n_samples,
                                                stamp_offsets=stamp_offsets)
    sett = stream_settings(g.n_samples, g.fs, nperseg=nperseg, noverlap=noverlap, window=window, detrend=detrend,
                           nfft=nfft)
    i0, i1 = (0, g.n_samples) if samples is None and time_range is None else (
        tuple(samples) if samples is not None else (g.index_of(time_range[0]), g.index_of(time_range[1])))
    if i1 <= i0:
        raise ValueError(f"the range [{i0}, {i1}) of grid samples is empty")
    if block_samples < 1:
        raise ValueError(f"{block_samples=} must be at least 1")
    acc = _new_accumulator(len(g.channels), g.fs, sett)
    notes: list[str] = list(g.warnings)
    missing = 0
    runs = _GapFree(i0)
    from vibroscope.faults import OVERFLOW_LIMIT

    huge = 0
    for blk in g.blocks(block_samples, start=i0, stop=i1):
        d = blk.data
        fin = np.isfinite(d)
        over = np.abs(d) > OVERFLOW_LIMIT  # ±Inf too: already missing, not counted below
        over &= fin
        if over.any():  # no measurement (a corrupted value): missing, as the whole read masks it
            huge += int(over.sum())
            d = np.where(over, np.nan, d)
            fin &= ~over
        bad = ~fin.all(axis=0)
        missing += int(bad.sum())
        runs.add(~bad)
        if common_gaps:
            if bad.any():
                d = np.array(d)
                d[:, bad] = np.nan
        piece = max(_PIECE_SEGMENTS * acc.settings.step, 1)
        for j in range(0, d.shape[1], piece):
            acc.update(d[:, j : j + piece])
        notes += blk.meta["warnings"]
    if huge:
        notes.append(f"{g.path}: {huge} samples beyond ±{OVERFLOW_LIMIT:.0e} (no measurement) treated as missing")
    if missing:
        notes.append(f"{g.path}: {missing} of {i1 - i0} grid samples missing in at least one channel (gaps, lost "
                     f"chunks; never interpolated): the Welch segments touching them are skipped")
    return LogSpectra(sources=(str(g.path),), channels=g.channels, units=g.units, fs=g.fs, samples=i1 - i0,
                      accumulator=acc, settings=sett, warnings=tuple(notes),
                      ranges=((str(g.path), int(i0), int(i1)),), t0_ns=g.t0_ns,
                      gap_free=runs.result() if common_gaps else None)


class _GapFree:
    """The stretches of at least 16 samples free of gaps, from the masks of consecutive blocks."""

    def __init__(self, start: int):
        self.pos, self.open, self.runs = int(start), None, []

    def add(self, good: np.ndarray) -> None:
        a, b = true_runs(good)
        a, b = a + self.pos, b + self.pos
        if self.open is not None:
            if a.size and a[0] == self.pos:  # the stretch goes on across the block boundary
                a[0] = self.open
            elif self.pos - self.open >= 16:
                self.runs.append((self.open, self.pos))
            self.open = None
        end = self.pos + good.size
        if b.size and b[-1] == end:  # may go on in the next block
            self.open, a, b = int(a[-1]), a[:-1], b[:-1]
        long = b - a >= 16
        self.runs += zip(a[long].tolist(), b[long].tolist())
        self.pos = end

    def result(self) -> np.ndarray:
        runs = self.runs + ([(self.open, self.pos)] if self.open is not None and self.pos - self.open >= 16 else [])
        return np.array(runs, np.int64).reshape(-1, 2)


def _fitting_segments(gap_free: np.ndarray, start: int, nperseg: int) -> int:
    """Welch segments of `nperseg` (50 % overlap, starting at grid index `start`) inside the
    gap-free stretches."""
    step = nperseg - nperseg // 2
    first = -(-(gap_free[:, 0] - start) // step)  # first segment starting in the stretch
    last = (gap_free[:, 1] - nperseg - start) // step  # last one ending in it
    return int(np.maximum(last - first + 1, 0).sum())


def _fit_between_gaps(sp: LogSpectra) -> int:
    """The automatic `nperseg` of `sp`, halved (a power of two, at least 16) until at least 8
    segments fit between the gaps (:func:`vibroscope.pipeline._nperseg_for`, from the gap-free
    stretches instead of the samples)."""
    n = int(sp.settings["nperseg"])
    if sp.gap_free is None:
        return n
    start = sp.ranges[0][1]
    while n > 16 and _fitting_segments(sp.gap_free, start, n) < 8:
        n //= 2
    return n


def merge_spectra(parts: Sequence[LogSpectra]) -> LogSpectra:
    """Merge the sums of disjoint records (ranges of one log, or several logs).

    Parameters
    ----------
    parts : sequence of LogSpectra
        Same channels, rate and settings.

    Returns
    -------
    LogSpectra
        A new one (the parts are not changed): sums and counts added, sources, ranges and
        warnings concatenated, samples those covered by the ranges.

    Raises
    ------
    ValueError
        If `parts` is empty, or they differ in channels or a setting (named).
    """
    import copy

    if not parts:
        raise ValueError("no spectra to merge")
    first = parts[0]
    acc = copy.deepcopy(first.accumulator)
    for p in parts[1:]:
        if p.channels != first.channels:
            raise ValueError(f"cannot merge spectra of different channels: {first.channels} and {p.channels}")
        acc.merge(p.accumulator)
    ranges = tuple(r for p in parts for r in p.ranges)
    return replace(first, sources=tuple(dict.fromkeys(s for p in parts for s in p.sources)),
                   samples=_covered(ranges), accumulator=acc,
                   warnings=tuple(w for p in parts for w in p.warnings), ranges=ranges)


def _covered(ranges) -> int:
    """Grid samples covered by (log, i0, i1) ranges, overlaps counted once."""
    total = 0
    for src in dict.fromkeys(r[0] for r in ranges):
        end = None
        for _, a, b in sorted(r for r in ranges if r[0] == src):
            if end is None or a >= end:
                total += b - a
                end = b
            elif b > end:
                total += b - end
                end = b
    return total


#: what :func:`analyse_stream` returns: the one result type of an analysis,
#: :class:`vibroscope.pipeline.Analysis`, with ``spectra`` (the accumulated sums) and no ``signals``
StreamAnalysis = Analysis


def _modes_from_spectra(G: CrossSpectralMatrix, input: str | None, outputs: list[str], *, fmin, fmax, n_modes,
                        estimator: str, prominence: float, method: str, select, notes: list):
    """(FRF or None, Identification, band) from a cross-spectral matrix."""
    from vibroscope.modal.methods import identify
    from vibroscope.modal.selection import MIN_BAND_LINES, excited_band, response_band

    f = G.frequencies
    nyq = 0.4 * G.settings["fs"]
    # (merge_duplicates=False: the streamed analysis has never merged duplicate candidates)
    if input:
        lo_x, hi_x = excited_band(f, G.G[:, G.index(input), G.index(input)].real)
        band = (max(fmin or 0.0, lo_x), min(fmax if fmax is not None else nyq, hi_x))
        notes.append(f"band from the input: {lo_x:.4g}–{hi_x:.4g} Hz (its PSD within 20 dB of the maximum)")
        h = frf(G, input, outputs, estimator=estimator)
        ident = identify(method, frf=h, time_series=False, fmin=fmin, fmax=band[1], band=band, n_modes=n_modes,
                         select=select, merge_duplicates=False)
        return h, ident, band
    Gout = G.select(outputs)
    P = np.stack([Gout.G[:, i, i].real for i in range(len(outputs))])
    f_low, hi_r = response_band(f, P, fmin=fmin)
    hi = fmax if fmax is not None else hi_r
    if fmax is None:
        notes.append(f"band from the response: lowest resonance {f_low:.4g} Hz, 95 % of the variance below "
                     f"{hi_r:.4g} Hz")
        lines = f[(f > 0) & (f >= (fmin or 0.0))]
        if lines.size > MIN_BAND_LINES and np.count_nonzero(lines <= hi) < 2 * MIN_BAND_LINES:
            hi = float(lines[min(2 * MIN_BAND_LINES, lines.size) - 1])  # a band of a few lines holds no peak
            notes.append(f"band widened to {hi:.4g} Hz: {2 * MIN_BAND_LINES} frequency lines at least")
    if method == "auto":
        notes.append("output-only modes by EFDD on the spectra (SSI-COV needs the time series, which a streamed "
                     "analysis does not hold)")
    ident = identify(method, csd=Gout, time_series=False, fmin=fmin, fmax=hi, n_modes=n_modes, prominence=prominence,
                     select=select, merge_duplicates=False)
    return None, ident, (fmin, hi)


def analyse_stream(path: str | Path | LogSpectra, *, input: str | None = None, outputs: Sequence[str] | None = None,
                   fs: float | None = None, nperseg: int | None = None, window: str = "hann",
                   fmin: float | None = None, fmax: float | None = None, n_modes: int | None = None,
                   estimator: str = "H1", prominence: float = 10.0, method: str = "auto",
                   select: Sequence[float] | None = None, block_samples: int = BLOCK_SAMPLES) -> Analysis:
    """Spectra, FRFs, coherence and modes of a log read block by block (memory bounded by the block).

    Parameters
    ----------
    path : str or Path or LogSpectra
        The MCAP log, or spectra already accumulated (e.g. merged over a fleet).
    input : str, optional
        The force channel (message path); with it FRFs and LSCF + LSFD, without it FDD/EFDD.
    outputs : sequence of str, optional
        Response channels; default every Imu ``linear_acceleration`` field, or in a log with no
        Imu topic the moving measurement fields of its busiest topic
        (:func:`vibroscope.io.blocks.open_grid`); with a log, channels that never move are left out.
    fs : float, optional
        Grid rate in Hz; default the highest topic rate.
    nperseg : int, optional
        Welch segment length; default :func:`stream_settings`.
    window : str, optional
        Welch window; default Hann.
    fmin, fmax : float, optional
        Band (Hz) searched for modes; default from the spectra (see the module notes).
    n_modes : int, optional
        Modes to report (peak picking and FDD); default every clear peak.
    estimator : {'H1', 'H2', 'Hv'}, optional
        FRF estimator with an input.
    prominence : float, optional
        Smallest peak prominence in dB for FDD/EFDD; default 10.
    method : str, optional
        A method of :data:`vibroscope.modal.methods.METHOD_CHOICES` that needs no time series
        ('auto', 'lscf', 'peak', 'fdd', 'efdd'; 'polymax' with an input is LSCF); 'auto': LSCF
        with an input, EFDD without.
    select : sequence of float, optional
        LSCF: the modes at these frequencies (Hz) from the stabilization diagram.
    block_samples : int, optional
        Grid samples read at a time; default 2**16.

    Returns
    -------
    Analysis
        :class:`vibroscope.pipeline.Analysis` with ``spectra`` (the accumulated sums, which
        :func:`merge_spectra` merges with other logs') and no ``signals`` (``streamed`` True).

    Raises
    ------
    LogFormatError, ChannelError
        If the log or a channel cannot be read (named).
    ValueError
        If a setting does not fit (a method needing the time series, an input for an
        output-only method, ``fmin > fmax``), or a channel has no segment free of gaps.
    """
    from vibroscope import modal
    from vibroscope.modal.methods import resolve_method

    resolve_method(method, has_input=bool(input), time_series=False)  # before reading the log
    if fmin is not None and fmax is not None and fmin > fmax:
        raise ValueError(f"{fmin=} Hz must not exceed {fmax=} Hz: swap them")
    if isinstance(path, LogSpectra):
        sp = path
    else:
        from vibroscope.io.blocks import open_grid

        chans = None if outputs is None and input is None else ([input] if input else []) + list(outputs or [])
        if input and outputs is None:
            g0 = open_grid(path, None, fs=fs, exclude_topics=(input.split(".", 1)[0],))  # a force is no response
            chans = [input] + [c for c in g0.channels if c != input]
        grid = open_grid(path, chans, fs=fs)  # planned once: the first pass and every refinement read it
        sp = accumulate_log(path, grid=grid, nperseg=nperseg, window=window, block_samples=block_samples)
        nfit = sp.settings["nperseg"] if nperseg is not None else _fit_between_gaps(sp)
        if nfit < sp.settings["nperseg"]:  # as analyse_signals: the automatic segment shortened to fit
            # between the gaps (the first pass learnt where they are): one more pass over the log
            first = sp.settings["nperseg"]
            sp = accumulate_log(path, grid=grid, nperseg=nfit, window=window, block_samples=block_samples)
            sp = replace(sp, warnings=sp.warnings + (
                f"nperseg {first} -> {nfit} (df {sp.fs / first:.4g} -> {sp.fs / nfit:.4g} Hz) so that 8 or more "
                f"segments fit between the gaps (one more pass over the log)",))
    refinements: list[int] = []
    while True:
        G, h, ident, band, outs, notes = _analyse_spectra(sp, input, outputs, fmin=fmin, fmax=fmax, n_modes=n_modes,
                                                          estimator=estimator, prominence=prominence, method=method,
                                                          select=select)
        # as analyse_signals: refine the resolution (another pass over the log) while an identified mode's
        # half-power band spans fewer than 8 bins and >= 5 averages remain
        bw = 2 * np.asarray(ident.modes.damping_ratios) * np.asarray(ident.modes.natural_frequencies)
        nper = sp.settings["nperseg"]
        if (isinstance(path, LogSpectra) or nperseg is not None or not input
                or not np.any(np.isfinite(bw) & (bw < 8 * sp.fs / nper)) or 2 * nper > 2 * sp.samples / 6
                or (sp.gap_free is not None and _fitting_segments(sp.gap_free, sp.ranges[0][1], 2 * nper) < 5)
                or len(refinements) >= 3):
            break
        refinements.append(nper)
        sp = accumulate_log(path, grid=grid, nperseg=2 * nper, window=window, block_samples=block_samples)
    if refinements:
        notes.append(f"resolution refined for the damping: nperseg {refinements[0]} -> {sp.settings['nperseg']} "
                     f"(df {sp.fs / refinements[0]:.4g} -> {sp.fs / sp.settings['nperseg']:.4g} Hz; one more pass "
                     f"over the log each)")
    Gout = G.select(outs)
    acc = sp.accumulator
    notes.append(f"streamed: {sp.samples} grid samples at {sp.fs:g} Hz from {len(sp.sources)} log(s), "
                 f"{acc.n_segments} Welch segments (nperseg={sp.settings['nperseg']}), read block by block")
    settings = dict(G.settings, fmin=fmin, fmax=band[1], estimator=estimator if input else None, input=input,
                    outputs=list(outs), method=ident.modes.method, band_hz=list(band), streamed=True,
                    n_samples=sp.samples)
    return Analysis(signals=None, spectra=sp, psd=G.psd(), csd=Gout, frf=h, modal=ident.modes,
                    singular_values=modal.singular_values(Gout), identification=ident, settings=settings, warnings=notes)


def _analyse_spectra(sp: LogSpectra, input, outputs, **kw):
    """(G of input + responses, FRF or None, Identification, band, responses, notes) of accumulated spectra."""
    notes = list(dict.fromkeys(sp.warnings))
    acc = sp.accumulator
    diag = acc.auto_sums()
    outs = [c for c in sp.channels if c != input] if outputs is None else list(outputs)
    count = np.diag(acc.n_averages)
    none = [c for c in outs if count[sp.channels.index(c)] == 0]
    if none and len(none) == len(outs):
        raise ValueError(f"no response channel has a segment of nperseg={sp.settings['nperseg']} samples free of "
                         f"gaps ({none[:3]}{' ...' if len(none) > 3 else ''}): give a smaller --nperseg")
    flat = [c for c in outs if diag[sp.channels.index(c)] == 0 and c not in none]
    if none:
        notes.append(f"{len(none)} channels with no segment free of gaps skipped: {none[:3]}")
        outs = [c for c in outs if c not in none]
    if flat:
        notes.append(f"{len(flat)} constant channels skipped (no vibration): {flat[:3]}")
        outs = [c for c in outs if c not in flat]
    if not outs:
        raise ValueError("no non-constant response channel to analyse")
    G = sp.csd()
    keep = ([input] if input else []) + outs
    G = G.select(keep)
    with _warnings.catch_warnings():  # few averages: said by the settings
        _warnings.simplefilter("ignore")
        h, ident, band = _modes_from_spectra(G, input, outs, notes=notes, **kw)
    return G, h, ident, band, outs, notes
