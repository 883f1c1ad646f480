"""A live, progressive rerun view of a record read block by block (issue #9, target 5).

:class:`LiveView` takes consecutive :class:`~vibroscope.signals.Signals` blocks (same channels and
rate, each starting where the previous one ended), logs each block's time series as it arrives
(decimated to a min/max envelope, :func:`vibroscope.viewers.rerun_series.envelope_indices`), feeds
the one-pass cross-spectral engine (:class:`vibroscope.spectral._engine.CrossSpectralAccumulator`)
and, every `every_blocks` blocks or `every_s` seconds, logs the PSD, the FRF (H1 by default) and
the coherence computed from the cross-spectral matrix accumulated so far: Welch's estimate
refined average by average (progressive Welch [1]_). A final refresh after the last block logs
the spectra of the whole record, equal to :func:`vibroscope.spectral.csd_matrix` and
:func:`vibroscope.spectral.frf` of it.

The block source is any iterable of ``Signals``: :func:`record_blocks` slices one in memory;
:func:`vibroscope.commands._live.mcap_blocks` reads a log block by block, and
:func:`vibroscope.commands._live.stream_log` (``vibroscope analyse LOG --connect``) opens the
log, chooses its channels and segment length and streams it here: this module only draws.

rerun is imported inside the functions: importing this module never imports it.

Entities and timelines
----------------------
``/signals/<channel>`` (timeline ``time``, s since the first sample)
    The samples of each block as it arrives (:class:`rerun.Scalars`), at most
    `block_points` per block and channel (its min/max envelope beyond that).
``/live/psd/<channel>``, ``/live/frf/magnitude_db/<output>``, ``/live/frf/phase_deg/<output>``, ``/live/frf/coherence/<output>``
    At each refresh, a :class:`rerun.BarChart` over frequency (the ``abscissa``, Hz, static)
    of ``10 log10`` PSD, ``20 log10 |H|``, the phase in degrees and γ², on the timelines
    ``time`` (the end of the data read so far) and ``averages`` (the number of segments
    averaged so far): a viewer following ``time`` shows the latest estimate while the log is
    read; scrubbing back shows earlier ones.
``/live/n_averages`` (timeline ``time``)
    The number of segments averaged at each refresh, a scalar series.
``/psd/<channel>``, ``/frf/{magnitude_db,phase_deg,coherence}/<output>`` (timeline ``frequency_mHz``)
    At the final refresh, the spectra of the whole record exactly as
    :func:`vibroscope.viewers.rerun_view.log_analysis` logs them (full resolution).

References
----------
.. [1] P. D. Welch, "The use of the fast Fourier transform for the estimation of power spectra",
   IEEE Trans. Audio Electroacoust. AU-15, 70–73, 1967.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator, Literal, Sequence

import numpy as np

from vibroscope.signals import Signals, block_bounds
from vibroscope.viewers.rerun_paths import channel_entity, frequency_index
from vibroscope.viewers.rerun_series import envelope_indices

__all__ = ["LiveView", "LiveRefresh", "live_blueprint", "record_blocks", "stream_blocks"]


@dataclass(frozen=True, eq=False, kw_only=True)
class LiveRefresh:
    """What one refresh of a :class:`LiveView` computed and logged.

    Attributes
    ----------
    n_averages : int
        Segments averaged so far (:attr:`CrossSpectralAccumulator.n_segments`).
    time_s : float
        End of the data read so far, in s since the first sample (the refresh's time on the
        ``time`` timeline).
    csd : CrossSpectralMatrix
        The cross-spectral matrix of the record so far (``G[f, i, j]``, density, unit²/Hz).
    psd : Spectrum
        Its diagonal.
    frf : FRF or None
        The FRF from the input channel to the others with its coherence; None without input.
    final : bool
        True for the refresh after the last block.
    """

    n_averages: int
    time_s: float
    csd: Any
    psd: Any
    frf: Any
    final: bool


class LiveView:
    """Log a record block by block to a rerun recording, with progressive Welch spectra.

    Parameters
    ----------
    rec : rerun.RecordingStream
        Where to log: connected (:func:`rerun.RecordingStream.connect_grpc`), spawned, serving or
        saving; its sinks are set by the caller, and :meth:`close` does not disconnect it.
    fs : float
        Sampling frequency of every block in Hz.
    channels : sequence of str
        Channel names of every block, in order.
    units : sequence of str, optional
        Units per channel (default ``""``).
    input : str, optional
        Input (force) channel: the FRF from it to every other channel is logged with the
        coherence. Without it, only the PSDs.
    nperseg : int, optional
        Welch segment length in samples (default 4096).
    noverlap : int, optional
        Overlap in samples (default ``nperseg // 2``).
    window : str, tuple or array_like, optional
        Window (default periodic Hann).
    detrend : {'constant', 'linear', False}, optional
        Per-segment detrending (default ``'constant'``).
    estimator : {'H1', 'H2', 'Hv'}, optional
        FRF estimator (default H1).
    every_blocks : int or None, optional
        Refresh the spectra every this many blocks (default 10); None: only on time.
    every_s : float or None, optional
        Refresh the spectra when this many seconds of wall time have passed since the last
        refresh (default 1.0); None: only on block count.
    block_points : int or None, optional
        Most points logged per block and channel (default 2000: a block longer than that is
        logged as its min/max envelope over 1000 bins); None logs every sample.
    clock : callable, optional
        Wall clock in s for `every_s` (default :func:`time.monotonic`).

    Raises
    ------
    ValueError
        If a setting is invalid (`fs` not positive, `input` not one of `channels` or the only
        one, `estimator` unknown, `every_blocks` < 1, `every_s` <= 0, or a Welch setting), or both
        `every_blocks` and `every_s` are None.

    Notes
    -----
    The spectra of a refresh are those of the record so far: every complete segment of
    `nperseg` samples that fits before the end of the last block is averaged (a segment
    straddling two blocks is carried over exactly), so after the last block they equal
    :func:`vibroscope.spectral.csd_matrix` and :func:`vibroscope.spectral.frf` of the whole record,
    and after any block they equal those of the record up to that block. Missing samples (NaN)
    are handled as there: a segment touching one is left out of every pair with that channel.

    Examples
    --------
    >>> import rerun as rr  # doctest: +SKIP
    >>> rec = rr.RecordingStream("vibroscope"); rec.connect_grpc()  # doctest: +SKIP
    >>> view = LiveView(rec, fs=sig.fs, channels=sig.channels, input="/force.x")  # doctest: +SKIP
    >>> last = view.run(record_blocks(sig, 1000))  # doctest: +SKIP
    """

    def __init__(self, rec, *, fs: float, channels: Sequence[str], units: Sequence[str] | None = None,
                 input: str | None = None, nperseg: int | None = 4096, noverlap: int | None = None,
                 window: Any = "hann", detrend: Literal["constant", "linear", False] = "constant",
                 estimator: Literal["H1", "H2", "Hv"] = "H1", every_blocks: int | None = 10,
                 every_s: float | None = 1.0, block_points: int | None = 2000,
                 clock: Callable[[], float] = time.monotonic):
        from vibroscope._checks import check_option
        from vibroscope.spectral import CrossSpectralAccumulator, segment_settings

        fs = float(fs)
        if not (np.isfinite(fs) and fs > 0):
            raise ValueError(f"{fs=} must be a positive sampling frequency in Hz")
        self.channels = tuple(str(c) for c in channels)
        self.units = tuple(units) if units is not None else ("",) * len(self.channels)
        if len(self.units) != len(self.channels):
            raise ValueError(f"{len(self.units)=} must equal {len(self.channels)=}")
        if input is not None and input not in self.channels:
            raise ValueError(f"{input=} is not one of the channels {self.channels}")
        if input is not None and len(self.channels) < 2:
            raise ValueError(f"{input=} is the only channel: an FRF needs an output channel too")
        check_option("estimator", estimator, ("H1", "H2", "Hv"))
        if every_blocks is None and every_s is None:
            raise ValueError("every_blocks and every_s are both None: the spectra would never refresh before the end")
        if every_blocks is not None and every_blocks < 1:
            raise ValueError(f"{every_blocks=} must be at least 1 (or None)")
        if every_s is not None and not every_s > 0:
            raise ValueError(f"{every_s=} must be positive (or None)")
        if block_points is not None and block_points < 2:
            raise ValueError(f"{block_points=} must be at least 2 (or None)")
        self.rec = rec
        self.fs = fs
        self.input = input
        self.estimator = estimator
        self.every_blocks = every_blocks
        self.every_s = every_s
        self.block_points = block_points
        self._clock = clock
        self.settings = segment_settings(None, nperseg=nperseg, noverlap=noverlap, window=window, detrend=detrend)
        self._acc = CrossSpectralAccumulator(len(self.channels), fs, self.settings)
        self.frequencies = self._acc.frequencies()
        self.ftl, self.fidx = frequency_index(self.frequencies)
        self.n_samples = 0
        self.n_blocks = 0
        self.t0: float | None = None
        self.refreshes: list[LiveRefresh] = []
        self._since = 0
        self._last = clock()
        self._closed = False
        self._log_static()

    # -- public ----------------------------------------------------------------------------
    @property
    def last(self) -> LiveRefresh | None:
        """The latest refresh, or None before the first."""
        return self.refreshes[-1] if self.refreshes else None

    def update(self, block: Signals) -> LiveRefresh | None:
        """Log the next block and feed it to the accumulator; refresh the spectra when due.

        Parameters
        ----------
        block : Signals
            The next `n` samples of every channel: the same channels and `fs` as the view, and
            ``t0`` equal to the previous block's end (within half a sample).

        Returns
        -------
        LiveRefresh or None
            The refresh logged after this block, None when none was due (or no complete segment
            has been averaged yet).

        Raises
        ------
        ValueError
            If the block's channels or rate differ from the view's, it does not start where the
            previous block ended, or the view is closed.
        """
        if self._closed:
            raise ValueError("the live view is closed: no block can follow close()")
        self._check(block)
        if self.t0 is None:
            self.t0 = float(block.t0)
        self._log_block(block)
        self._acc.update(block.data)
        self.n_samples += block.n_samples
        self.n_blocks += 1
        self._since += 1
        due = (self.every_blocks is not None and self._since >= self.every_blocks) or (
            self.every_s is not None and self._clock() - self._last >= self.every_s)
        if due and self._acc.n_segments:
            return self.refresh()
        return None

    def refresh(self, *, final: bool = False) -> LiveRefresh:
        """Compute the spectra from what was accumulated and log them now.

        Parameters
        ----------
        final : bool, optional
            Also log the full-resolution spectra on the frequency timeline (``/psd``, ``/frf``),
            as :func:`vibroscope.viewers.rerun_view.log_analysis` does; default False.

        Returns
        -------
        LiveRefresh

        Raises
        ------
        ValueError
            If no complete segment of `nperseg` samples has been fed yet.
        """
        import rerun as rr

        from vibroscope.spectral import CrossSpectralMatrix
        from vibroscope.spectral.estimators import settings_dict, frf as frf_of
        from vibroscope.viewers.rerun_spectra import decibels

        acc = self._acc
        if not acc.n_segments:
            raise ValueError(f"no complete segment yet: {self.n_samples} samples fed, nperseg={self.settings.nperseg}")
        st = self.settings
        cnt = acc.n_averages
        settings = settings_dict(self.fs, st, int(cnt.min()), acc.n_segments)
        with np.errstate(divide="ignore", invalid="ignore"):
            csd = CrossSpectralMatrix(frequencies=self.frequencies, G=acc.result("density"), channels=self.channels,
                                      units=self.units,
                                      scaling="density", settings=settings, n_averages=cnt)
            psd = csd.psd()
            frf = None
            if self.input is not None:
                frf = frf_of(csd, [self.input], estimator=self.estimator)
        end_s = self.n_samples / self.fs
        out = LiveRefresh(n_averages=acc.n_segments, time_s=end_s, csd=csd, psd=psd, frf=frf, final=final)
        rec = self.rec
        prev = self.last
        if final and prev is not None and prev.time_s == end_s:  # nothing read since: no second live row
            self._log_final(out)
            self.refreshes[-1] = out
            return out
        rec.set_time("time", duration=np.timedelta64(int(round(end_s * 1e9)), "ns"))
        rec.set_time("averages", sequence=acc.n_segments)
        rec.log("/live/n_averages", rr.Scalars(float(acc.n_segments)))
        for k, ch in enumerate(self.channels):
            rec.log(channel_entity("live/psd", ch), rr.BarChart(decibels(psd.values[k])))
        if frf is not None:
            for o, out_ch in enumerate(frf.outputs):
                h = frf.H[:, o, 0]
                rec.log(channel_entity("live/frf/magnitude_db", out_ch),
                        rr.BarChart(decibels(np.abs(h), 20.0)))
                rec.log(channel_entity("live/frf/phase_deg", out_ch),
                        rr.BarChart(np.degrees(np.angle(h))))
                rec.log(channel_entity("live/frf/coherence", out_ch),
                        rr.BarChart(np.asarray(frf.coherence[:, o], dtype=np.float64)))
        rec.reset_time()
        if final:
            self._log_final(out)
        self.refreshes.append(out)
        self._since = 0
        self._last = self._clock()
        return out

    def _log_final(self, out: LiveRefresh) -> None:
        from vibroscope.viewers.rerun_spectra import log_frf, log_psd

        log_psd(self.rec, out.psd)
        if out.frf is not None:
            log_frf(self.rec, out.frf)

    def close(self) -> LiveRefresh | None:
        """The final refresh: the spectra of the whole record, also on the frequency timeline.

        The recording is neither flushed nor disconnected (the caller owns its sinks; a flush
        without timeout waits for ever when no viewer listens at a gRPC sink).

        Returns
        -------
        LiveRefresh or None
            None when the record was shorter than one segment (nothing to average).
        """
        self._closed = True
        if not self._acc.n_segments:
            return None
        return self.refresh(final=True)

    def run(self, blocks: Iterable[Signals]) -> LiveRefresh | None:
        """Feed every block of `blocks` (:meth:`update`), then :meth:`close`.

        Parameters
        ----------
        blocks : iterable of Signals
            Consecutive blocks, e.g. :func:`record_blocks` or :func:`vibroscope.commands._live.mcap_blocks`.

        Returns
        -------
        LiveRefresh or None
            The final refresh (see :meth:`close`).
        """
        for b in blocks:
            self.update(b)
        return self.close()

    # -- internals -------------------------------------------------------------------------
    def _check(self, block: Signals) -> None:
        if tuple(block.channels) != self.channels:
            raise ValueError(f"block channels {tuple(block.channels)} differ from the view's {self.channels}")
        if float(block.fs) != self.fs:
            raise ValueError(f"block fs={block.fs} Hz differs from the view's fs={self.fs} Hz")
        if self.t0 is not None:
            expected = self.t0 + self.n_samples / self.fs
            if abs(float(block.t0) - expected) > 0.5 / self.fs:
                raise ValueError(f"block t0={block.t0:.9g} s does not follow the previous block (expected "
                                 f"{expected:.9g} s): blocks must be consecutive")

    def _log_static(self) -> None:
        import rerun as rr

        rec = self.rec
        # the frequency axis (Hz) of the bar charts, once (BarChart.from_fields cannot take it alone in 0.41)
        axis = [rr.components.TensorDataBatch(rr.encodings.TensorData(array=self.frequencies))
                .described(rr.BarChart.descriptor_abscissa())]
        for k, ch in enumerate(self.channels):
            rec.log(channel_entity("signals", ch), rr.SeriesLines(names=f"{ch} [{self.units[k] or '-'}]"), static=True)
            rec.log(channel_entity("live/psd", ch), axis, static=True)
        if self.input is not None:
            for ch in self.channels:
                if ch != self.input:
                    for what in ("magnitude_db", "phase_deg", "coherence"):
                        rec.log(channel_entity(f"live/frf/{what}", ch), axis, static=True)
        rec.log("/live/n_averages", rr.SeriesLines(names="segments averaged"), static=True)
        st = self.settings
        rec.log("about", rr.TextDocument(
            "\n".join(["# vibroscope live analysis", "",
                       "- `time` — time series as read (seconds since the first sample); the `/live` bar charts "
                       "show the spectra of the data read so far (progressive Welch), latest at the cursor;",
                       "- `averages` — the same refreshes by number of segments averaged;",
                       f"- `{self.ftl}` — the final spectra of the whole record (index: frequency in "
                       + ("µHz" if self.ftl == "frequency_uHz" else "mHz") + ")", "",
                       f"Welch: fs={self.fs:g} Hz, nperseg={st.nperseg}, noverlap={st.noverlap}, "
                       f"window={st.window_spec if isinstance(st.window_spec, (str, tuple)) else 'custom'}, "
                       f"detrend={st.detrend}; PSD in dB re 1 unit²/Hz"
                       + (f"; FRF {self.estimator} from {self.input}" if self.input else "")]),
            media_type=rr.MediaType.MARKDOWN), static=True)

    def _log_block(self, block: Signals) -> None:
        import rerun as rr

        rec = self.rec
        for k, ch in enumerate(self.channels):
            x = np.asarray(block.data[k], dtype=np.float64)
            keep = envelope_indices(x, self.block_points)
            if not keep.size:
                continue
            t_ns = np.round((self.n_samples + keep) / self.fs * 1e9).astype(np.int64).astype("timedelta64[ns]")
            rec.send_columns(channel_entity("signals", ch), indexes=[rr.TimeColumn("time", duration=t_ns)],
                             columns=rr.Scalars.columns(scalars=x[keep]))


def live_blueprint(view: LiveView):
    """The viewer layout of a live analysis: a live tab (time series beside the latest spectra,
    timeline ``time``, following), the final spectra and FRF tabs (frequency timeline), About.

    Parameters
    ----------
    view : LiveView
        The view whose channels and input set the panels.

    Returns
    -------
    rerun.blueprint.Blueprint
    """
    import rerun.blueprint as rrb

    ts = [rrb.TimeSeriesView(origin=channel_entity("signals", c), name=f"{c} [{u or '-'}] (timeline: time)")
          for c, u in zip(view.channels, view.units)]
    live = [rrb.BarChartView(origin=channel_entity("live/psd", c), name=f"PSD so far [dB] {c}") for c in view.channels]
    if view.input is not None:
        outs = [c for c in view.channels if c != view.input]
        live += [rrb.BarChartView(origin=channel_entity("live/frf/coherence", c), name=f"coherence so far {c}")
                 for c in outs]
        live += [rrb.BarChartView(origin=channel_entity("live/frf/magnitude_db", c), name=f"|H| so far [dB] {c}")
                 for c in outs]
    cols = 1 if len(ts) <= 4 else 2
    tabs = [rrb.Horizontal(rrb.Vertical(rrb.Grid(*ts, grid_columns=cols),
                                        rrb.TimeSeriesView(origin="/live/n_averages", name="segments averaged"),
                                        row_shares=[4, 1]),
                           rrb.Grid(*live, grid_columns=cols), name="Live (timeline: time)"),
            rrb.TimeSeriesView(origin="/psd", name=f"PSD of the whole record [dB] ({view.ftl})")]
    if view.input is not None:
        tabs.append(rrb.Vertical(
            rrb.TimeSeriesView(origin="/frf/magnitude_db", name=f"FRF magnitude [dB] ({view.ftl})"),
            rrb.TimeSeriesView(origin="/frf/phase_deg", name=f"FRF phase [deg] ({view.ftl})"),
            rrb.TimeSeriesView(origin="/frf/coherence", name=f"coherence γ² ({view.ftl})"),
            name=f"FRF (timeline: {view.ftl})"))
    tabs.append(rrb.TextDocumentView(origin="/about", name="About"))
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), rrb.TimePanel(timeline="time", play_state="following"),
                         collapse_panels=False)


def record_blocks(sig: Signals, block_size: int) -> Iterator[Signals]:
    """Consecutive blocks of `block_size` samples of a record in memory (the last may be shorter).

    Parameters
    ----------
    sig : Signals
        The record.
    block_size : int
        Samples per block.

    Yields
    ------
    Signals
        Views of ``sig.data`` (no copy), ``t0`` advanced block by block, ``meta``
        ``{"n_samples_total": sig.n_samples}``.

    Raises
    ------
    ValueError
        If `block_size` is not positive.
    """
    if block_size < 1:
        raise ValueError(f"{block_size=} must be a positive number of samples")
    for a, b in block_bounds(int(block_size), sig.n_samples):
        yield Signals(data=sig.data[:, a:b], fs=sig.fs, channels=sig.channels, units=sig.units, t0=sig.t0 + a / sig.fs,
                      meta={"n_samples_total": sig.n_samples})


def stream_blocks(blocks: Iterable[Signals], rec, *, input: str | None = None, nperseg: int | None = 4096,
                  estimator: Literal["H1", "H2", "Hv"] = "H1", every_blocks: int | None = 10,
                  every_s: float | None = 1.0, block_points: int | None = 2000,
                  send_blueprint: bool = True) -> LiveView:
    """Stream `blocks` to `rec` through a :class:`LiveView` set up from the first block.

    Parameters
    ----------
    blocks : iterable of Signals
        Consecutive blocks (their channels, units and rate set the view).
    rec : rerun.RecordingStream
        The recording (connected, spawned, serving or saving).
    input : str, optional
        Input channel for the FRF.
    nperseg : int, optional
        Welch segment length (default 4096).
    estimator : {'H1', 'H2', 'Hv'}, optional
        FRF estimator (default H1).
    every_blocks : int or None, optional
        Refresh every this many blocks (default 10).
    every_s : float or None, optional
        Refresh at least every this many seconds of wall time (default 1.0).
    block_points : int or None, optional
        Most time-series points per block and channel (default 2000).
    send_blueprint : bool, optional
        Send :func:`live_blueprint` to the recording (default True).

    Returns
    -------
    LiveView
        Closed; its :attr:`LiveView.refreshes` hold every refresh, the last the final one.

    Raises
    ------
    ValueError
        If `blocks` is empty, or as :class:`LiveView`.
    """
    it = iter(blocks)
    first = next(it, None)
    if first is None:
        raise ValueError("no block to stream: the source yielded nothing")
    view = LiveView(rec, fs=first.fs, channels=first.channels, units=first.units, input=input, nperseg=nperseg,
                    estimator=estimator, every_blocks=every_blocks, every_s=every_s, block_points=block_points)
    if send_blueprint:
        rec.send_blueprint(live_blueprint(view))
    view.update(first)
    view.run(it)
    return view
