"""Scale-out on Dask: the cross-spectral accumulation of many logs spread over files and time ranges.

:func:`analyse_fleet` plans every log on the client (:func:`vibroscope.io.blocks.open_grid`: the
summary and one chunk at each end of each topic), chooses one set of Welch settings for all, splits
each log into grid-sample ranges at segment boundaries (:func:`vibroscope.stream.segment_ranges`),
and submits one task per range to a ``dask.distributed`` cluster. A task carries the log's path,
its range, its grid (rate, origin) and the settings — plain numbers, never arrays; each worker
reads its range block by block from the file (:func:`vibroscope.stream.accumulate_log`) and
returns the accumulator (``n_freqs × n_channels²`` sums), so the workers must see the files at the
same paths (a shared file system). The sums of a log's ranges merge into exactly the one-pass sums
of the log; the sums of all logs merge into the fleet's spectra (every segment of every log
averaged once; no segment straddles two logs).

Per log, one more task (on a worker, after the log's range tasks) merges the ranges and fills the
log's row of the fleet table (:class:`FleetRow`): the modes identified from the log's spectra
(:func:`vibroscope.stream.analyse_stream` on them: LSCF with an input, EFDD without) and the RMS of
each channel in each frequency band (octave bands by default). The client only plans the logs and
merges the per-log sums into the fleet's spectra.

A log that cannot be analysed (it cannot be planned, is shorter than a segment, has no segment
free of gaps, its rate is more than :data:`RATE_TOLERANCE` off the fleet's, or a range of it fails to
read) does not stop the fleet: its row carries the
``error`` (its spectra NaN, no modes), it is left out of the merged spectra and ``per_log``, and
``settings["excluded"]`` and ``settings["warnings"]`` name it. Only when no log can be analysed
does :func:`analyse_fleet` raise.

Dask is imported here only when :func:`analyse_fleet` runs (the ``[dask]`` extra).
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from vibroscope.stream import LogSpectra, merge_spectra, segment_ranges, stream_settings

__all__ = ["FleetRow", "FleetResult", "analyse_fleet", "local_cluster", "octave_bands", "band_rms", "WORKER_ENV",
           "RATE_TOLERANCE"]

#: a log whose rate is within this fraction of the fleet's is resampled onto it; further off, left out
RATE_TOLERANCE = 0.05


def octave_bands(fs: float, df: float) -> tuple[tuple[float, float], ...]:
    """Octave bands (centres 1000·2^k Hz, edges ``fc/√2 .. fc·√2``) between `df` and ``fs / 2``.

    Parameters
    ----------
    fs : float
        Sampling rate in Hz.
    df : float
        Frequency resolution in Hz (the lowest band's lower edge is at least this).

    Returns
    -------
    tuple of (float, float)
        (lower, upper) edges in Hz, increasing.
    """
    out = []
    for k in range(-12, 8):
        fc = 1000.0 * 2.0**k
        lo, hi = fc / np.sqrt(2), fc * np.sqrt(2)
        if lo >= df and hi <= fs / 2:
            out.append((float(lo), float(hi)))
    return tuple(out)


def band_rms(frequencies: np.ndarray, psd: np.ndarray, bands: Sequence[tuple[float, float]]) -> np.ndarray:
    """RMS of each channel in each band, from a one-sided PSD.

    Parameters
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Uniform frequency axis in Hz.
    psd : ndarray, shape (n_channels, n_freqs)
        One-sided PSD, unit²/Hz.
    bands : sequence of (float, float)
        (lower, upper) edges in Hz; bins with ``lower <= f < upper`` are summed.

    Returns
    -------
    ndarray, shape (n_channels, n_bands)
        ``sqrt(Σ P(f) df)`` in the channels' units (rectangle rule on the Welch lines).
    """
    f = np.asarray(frequencies, float)
    df = f[1] - f[0]
    P = np.atleast_2d(np.asarray(psd, float))
    out = np.empty((P.shape[0], len(bands)))
    for k, (lo, hi) in enumerate(bands):
        m = (f >= lo) & (f < hi)
        out[:, k] = np.sqrt(P[:, m].sum(axis=1) * df)
    return out


@dataclass(frozen=True, kw_only=True)
class FleetRow:
    """One log of the fleet table.

    Attributes
    ----------
    log : str
        The log's path.
    n_samples : int
        Grid samples of the log (its Welch segments leave out less than one hop at the end).
    duration_s : float
        ``n_samples / fs``.
    natural_frequencies, damping_ratios : tuple of float
        The modes identified from the log's spectra.
    bands_hz : tuple of (float, float)
        The bands of `rms`.
    channels : tuple of str
        The channels of `rms`.
    rms : tuple of tuple of float
        ``rms[c][b]``: RMS of channel c in band b (the channel's unit).
    error : str
        Why the modes could not be identified, or why the log could not be analysed at all (then
        `rms` is NaN and the log is not in the merged spectra); empty when all went well.
    warnings : tuple of str
        What reading the log noticed (samples missing in gaps or lost chunks, damage skipped,
        stamps), one line each, without repeats.
    """

    log: str
    n_samples: int
    duration_s: float
    natural_frequencies: tuple
    damping_ratios: tuple
    bands_hz: tuple
    channels: tuple
    rms: tuple
    error: str = ""
    warnings: tuple = ()

    def to_dict(self) -> dict:
        """A JSON-serialisable dict (NaN as None).

        Returns
        -------
        dict
        """
        def num(v):
            return float(v) if np.isfinite(v) else None

        return {"log": self.log, "n_samples": self.n_samples, "duration_s": self.duration_s,
                "modes": [{"frequency_hz": num(f), "damping_ratio": num(z)}
                          for f, z in zip(self.natural_frequencies, self.damping_ratios)],
                "rms": {c: {f"{lo:.4g}-{hi:.4g}Hz": num(v) for (lo, hi), v in zip(self.bands_hz, r)}
                        for c, r in zip(self.channels, self.rms)},
                "error": self.error, "warnings": list(self.warnings)}


@dataclass(frozen=True, eq=False)
class FleetResult:
    """What :func:`analyse_fleet` found.

    Attributes
    ----------
    rows : tuple of FleetRow
        The fleet table, one row per log, in the order given.
    per_log : dict of str to LogSpectra
        Each analysed log's accumulated spectra (exactly one pass over the log); the logs that
        could not be analysed are absent.
    merged : LogSpectra
        The analysed logs' sums merged (every segment of every such log averaged once).
    settings : dict
        Welch settings, rate, channels, bands, tasks and workers; ``excluded`` (the logs left
        out of the merged spectra) and ``warnings`` (why, one line each).
    """

    rows: tuple
    per_log: dict
    merged: LogSpectra
    settings: dict

    def to_rows(self) -> list[dict]:
        """The fleet table as flat rows (one per log) for a CSV.

        Returns
        -------
        list of dict
            ``log``, ``n_samples``, ``duration_s``, ``modes_hz`` and ``damping`` (``;``-joined),
            then per band ``rms_<lo>-<hi>Hz``: the largest channel RMS in the band, ``error``
            and ``warnings`` (`` | ``-joined).
        """
        out = []
        for r in self.rows:
            d = {"log": r.log, "n_samples": r.n_samples, "duration_s": f"{r.duration_s:.6g}",
                 "modes_hz": ";".join(f"{f:.6g}" for f in r.natural_frequencies),
                 "damping": ";".join(f"{z:.4g}" for z in r.damping_ratios)}
            rms = np.array(r.rms, float).reshape(len(r.channels), len(r.bands_hz))
            for k, (lo, hi) in enumerate(r.bands_hz):
                col = rms[:, k]
                d[f"rms_{lo:.4g}-{hi:.4g}Hz"] = f"{np.nanmax(col):.6g}" if np.isfinite(col).any() else ""
            d["error"] = r.error
            d["warnings"] = " | ".join(r.warnings)
            out.append(d)
        return out

    def write_csv(self, path: str | Path) -> Path:
        """Write :meth:`to_rows` as a CSV file.

        Parameters
        ----------
        path : str or Path
            The file.

        Returns
        -------
        Path
        """
        rows = self.to_rows()
        path = Path(path)
        with open(path, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["log"])
            w.writeheader()
            w.writerows(rows)
        return path

    def to_dict(self) -> dict:
        """The table and the merged spectra's summary, JSON-serialisable.

        Returns
        -------
        dict
            ``logs`` (:meth:`FleetRow.to_dict` each), ``settings``, ``merged`` (``channels``,
            ``n_samples``, ``n_segments``, ``psd_peak_hz`` per channel: None for a channel that
            never moves or has no segment).
        """
        G = self.merged.csd()
        P = G.psd().values
        f = G.frequencies
        peaks = {c: (float(f[1 + int(np.nanargmax(p[1:]))]) if np.nanmax(p[1:], initial=0.0) > 0 else None)
                 for c, p in zip(G.channels, np.nan_to_num(P, nan=0.0))}
        from vibroscope._checks import jsonable

        return {"logs": [r.to_dict() for r in self.rows], "settings": jsonable(self.settings),
                "merged": {"channels": list(G.channels), "n_samples": self.merged.samples,
                           "n_segments": self.merged.accumulator.n_segments, "psd_peak_hz": peaks}}

    def write_json(self, path: str | Path) -> Path:
        """Write :meth:`to_dict` as JSON.

        Parameters
        ----------
        path : str or Path
            The file.

        Returns
        -------
        Path
        """
        from vibroscope.provenance import json_report

        path = Path(path)
        path.write_text(json.dumps(json_report(self.to_dict()), indent=2))
        return path


@dataclass(frozen=True)
class _Failed:
    """What a task returns instead of raising: the log and why (so one bad log does not fail the fleet)."""

    log: str
    error: str


def _task(path: str, channels: tuple, fs: float, t0_ns: int, n_samples: int, stamp_offsets: tuple, samples: tuple,
          settings: dict) -> LogSpectra | _Failed:
    """One Dask task: accumulate grid samples `samples` of the log at `path` (runs on a worker); a
    failure is returned as :class:`_Failed`, not raised."""
    from vibroscope.stream import accumulate_log

    try:
        return accumulate_log(path, channels, fs=fs, t0_ns=t0_ns, n_samples=n_samples, stamp_offsets=stamp_offsets,
                              samples=samples, **settings)
    except Exception as exc:  # noqa: BLE001 - reported in the log's row: the other logs go on
        return _Failed(path, f"{type(exc).__name__}: {exc}")


def _failed_row(path: str, n_samples: int, fs: float, bands: tuple, channels: tuple, error: str) -> FleetRow:
    """The row of a log that could not be analysed: NaN band RMS, no modes, the error."""
    nan = tuple(tuple(float("nan") for _ in bands) for _ in channels)
    return FleetRow(log=path, n_samples=int(n_samples), duration_s=n_samples / fs, natural_frequencies=(),
                    damping_ratios=(), bands_hz=bands, channels=tuple(channels), rms=nan, error=error)


def _log_row(path: str, bands: tuple, channels: tuple, fs: float, opts: dict,
             *parts: LogSpectra | _Failed) -> tuple[LogSpectra | None, FleetRow]:
    """One Dask task per log, after its range tasks: merge them and fill its row of the fleet table
    (band RMS and modes), so that the per-log identification runs on the workers, not the client.
    A log that cannot be analysed gives (None, its row with the error)."""
    from vibroscope.stream import analyse_stream

    failed = [p.error for p in parts if isinstance(p, _Failed)]
    good = [p for p in parts if not isinstance(p, _Failed)]
    if failed or not good:
        why = failed[0] if failed else "no complete Welch segment"
        return None, _failed_row(path, 0, fs, bands, channels, f"not analysed: {why}")
    sp = merge_spectra(good)
    try:
        G = sp.csd()
    except ValueError as exc:  # no segment free of missing samples
        return None, _failed_row(path, sp.samples, fs, bands, channels, f"not analysed: {exc}")
    P = G.psd().values
    rms = band_rms(G.frequencies, P, bands)
    try:
        an = analyse_stream(sp, **opts)
        f_n, z, err = tuple(an.modal.natural_frequencies.tolist()), tuple(an.modal.damping_ratios.tolist()), ""
    except ValueError as exc:
        f_n, z, err = (), (), str(exc)
    return sp, FleetRow(log=path, n_samples=sp.samples, duration_s=sp.samples / fs, natural_frequencies=f_n,
                        damping_ratios=z, bands_hz=bands, channels=tuple(channels),
                        rms=tuple(tuple(r) for r in rms.tolist()), error=err,
                        warnings=tuple(dict.fromkeys(sp.warnings)))


#: glibc's mmap threshold set in worker processes: Dask's nannies set ``MALLOC_TRIM_THRESHOLD_``
#: (which freezes the threshold at 128 KiB), so every decompressed chunk and block array would be
#: a fresh mmap and its pages faulted in again: the accumulation ran 1.8x slower than in-process
WORKER_ENV = {"MALLOC_MMAP_THRESHOLD_": 32 << 20}


def local_cluster(n_workers: int | None = None, **kw: Any):
    """A ``dask.distributed.LocalCluster`` for :func:`analyse_fleet`: single-threaded worker processes,
    no dashboard, :data:`WORKER_ENV` in the workers' environment.

    Parameters
    ----------
    n_workers : int, optional
        Worker processes; default the machine's cores.
    **kw
        Passed to ``LocalCluster``.

    Returns
    -------
    dask.distributed.LocalCluster
    """
    import dask.config
    from dask.distributed import LocalCluster

    opts = dict(n_workers=n_workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                dashboard_address=None)
    opts.update(kw)
    env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}), **WORKER_ENV)
    with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
        return LocalCluster(**opts)


def _client(client: Any):
    """(Client, things to close): the one given, one connected to an address, or a LocalCluster."""
    from dask.distributed import Client

    if client is None:
        cluster = local_cluster()
        c = Client(cluster)
        return c, [c, cluster]
    if isinstance(client, str):
        c = Client(client)
        return c, [c]
    return client, []


def analyse_fleet(paths: Sequence[str | Path], *, client: Any = None, channels: Sequence[str] | None = None,
                  input: str | None = None, fs: float | None = None, nperseg: int | None = None,
                  window: str = "hann", bands: Sequence[tuple[float, float]] | None = None,
                  tasks_per_log: int | None = None, method: str = "auto", fmin: float | None = None,
                  fmax: float | None = None, find_input: bool = False) -> FleetResult:
    """Spectra, modes and band RMS of many logs, the accumulation spread over a Dask cluster.

    Parameters
    ----------
    paths : sequence of str or Path
        The MCAP logs (the workers read them at these paths).
    client : dask.distributed.Client or str, optional
        A client, or a scheduler address (``"tcp://host:8786"``); default
        :func:`local_cluster` (one single-threaded worker process per core, closed at the end).
    channels : sequence of str, optional
        Message paths, the same in every log; default those
        :func:`~vibroscope.io.blocks.open_grid` chooses in the first log that plans (the Imu
        ``linear_acceleration`` fields, else the moving measurement fields of its busiest topic),
        with `input` first when given.
    input : str, optional
        The force channel, for FRFs and LSCF per log.
    fs : float, optional
        Grid rate in Hz, every log resampled onto it. Default the median of the logs' rates: a
        log within :data:`RATE_TOLERANCE` of it is put on it (the rates of logs of one nominal
        rate differ in their estimates), a log further off gets its row's error and is left out.
    nperseg : int, optional
        Welch segment length for all logs; default :func:`vibroscope.stream.stream_settings` of
        the median-length log (a log shorter than one segment then gets its row's error and is
        left out of the merged spectra); given, the shortest log that holds a segment decides the
        rest of the settings.
    window : str, optional
        Welch window; default Hann.
    bands : sequence of (float, float), optional
        Bands (Hz) for the RMS; default :func:`octave_bands`.
    tasks_per_log : int, optional
        Ranges each log is split into; default enough for two tasks per worker over the fleet.
    method : str, optional
        A method of :data:`vibroscope.modal.methods.METHOD_CHOICES` that needs no time series
        ('auto', 'lscf', 'peak', 'fdd', 'efdd'); identification per log (:func:`vibroscope.stream.analyse_stream`).
    fmin, fmax : float, optional
        Band (Hz) searched for modes; default from each log's spectra.
    find_input : bool, optional
        Without `input`, the first log that plans chooses the input as it chooses the channels:
        its one force-like channel that moves (:meth:`vibroscope.io.blocks.LogGrid.force_input`),
        then the input of every log; the line saying so (or why none was taken) is
        ``settings["input_choice"]``. Default False.

    Returns
    -------
    FleetResult
        A log that cannot be analysed has its row's ``error`` filled and is left out of the
        merged spectra (``settings["excluded"]``, ``settings["warnings"]``).

    Raises
    ------
    ValueError
        If `paths` is empty, `method` is unknown or does not fit (spectra only, with or without
        `input`), or no log can be analysed (each named with its error).
    ImportError
        If ``dask.distributed`` is not installed (the ``[dask]`` extra).
    """
    from vibroscope.errors import VibroscopeError
    from vibroscope.io.blocks import open_grid
    from vibroscope.modal.methods import resolve_method

    paths = [str(p) for p in paths]
    if not paths:
        raise ValueError("no logs given")
    resolve_method(method, has_input=bool(input), time_series=False)  # as every log would, before any work
    fs_given = fs  # every log goes onto this rate when given
    errors: dict[int, str] = {}  # by position in `paths` (a log may be given twice)

    def plan(k, chans, rate, exclude=()):
        try:
            return open_grid(paths[k], chans, fs=rate, exclude_topics=exclude)
        except (VibroscopeError, ValueError, OSError) as exc:  # this log's row says why; the others go on
            errors[k] = f"not analysed: cannot be planned: {type(exc).__name__}: {exc}"
            return None

    def none_left():
        return ValueError("no log of the fleet can be analysed: " + "; ".join(f"{paths[k]}: {e}"
                                                                              for k, e in sorted(errors.items())))

    first, k0, choice = None, 0, None
    for k0 in range(len(paths)):  # the first log that plans chooses the channels and the rate
        first = plan(k0, channels, fs, (input.split(".", 1)[0],) if input and channels is None else ())
        if first is not None and find_input and input is None:  # and the input, as a whole read takes it
            found = first.force_input(exclude_channels=channels or ())
            choice = found.line() or None
            if found.channel:
                input = found.channel
                if channels is not None:
                    channels = [input, *(c for c in channels if c != input)]
                    first = plan(k0, channels, fs)
                else:  # its topic holds the force, not a response
                    first = plan(k0, None, fs, (input.split(".", 1)[0],))
        if first is not None and channels is None and input is not None:
            first = plan(k0, [input] + [c for c in first.channels if c != input], fs)
        if first is not None:
            break
    if first is None:
        raise none_left()
    channels = first.channels
    grids = [None if k < k0 else first if k == k0 else plan(k, channels, fs_given) for k in range(len(paths))]
    rates = [g.fs for g in grids if g is not None]
    fs = fs_given if fs_given is not None else sorted(rates)[(len(rates) - 1) // 2]  # the median log's rate
    resampled = []
    for k, g in enumerate(grids):
        if g is None or abs(g.fs - fs) <= 1e-9 * fs:
            continue
        if abs(g.fs - fs) > RATE_TOLERANCE * fs:  # another kind of log (or a broken clock): not mixed in
            errors[k] = (f"not analysed: rate {g.fs:.6g} Hz differs from the fleet's {fs:.6g} Hz (the median log's) "
                         f"by more than {100 * RATE_TOLERANCE:g} %: analyse the logs of one rate together, or give "
                         f"fs= (--fs) to resample every log")
            grids[k] = None
        else:  # the same nominal rate, each log's estimate a little off: onto the fleet's grid rate
            resampled.append(f"{paths[k]} ({g.fs:.6g} Hz)")
            grids[k] = plan(k, channels, fs)
    for g in filter(None, grids):
        g.fs = fs
    by_len = sorted((k for k, g in enumerate(grids) if g is not None), key=lambda k: grids[k].n_samples)
    if nperseg is None:  # the median log chooses the resolution (the shortest would coarsen every log's:
        # a 2.5 s log among 40 s ones gave nperseg 16); a log too short for it is left out, with the reason
        mid = len(by_len) // 2  # of two middle logs, the longer
        by_len = by_len[mid:] + by_len[:mid][::-1]
    sett = None
    for k in by_len:
        try:  # the first log in that order that takes the settings chooses them
            sett = stream_settings(grids[k].n_samples, fs, nperseg=nperseg, window=window)
            break
        except ValueError as exc:
            errors[k] = f"not analysed: {grids[k].n_samples} grid samples: {exc}"
    if sett is None:
        raise none_left()
    df = fs / sett["nfft"]
    bands = tuple(tuple(map(float, b)) for b in (bands if bands is not None else octave_bands(fs, df)))
    opts = dict(input=input, method=method, fmin=fmin, fmax=fmax)
    c, owned = _client(client)
    try:
        n_workers = max(1, len(c.scheduler_info().get("workers", {})) or 1)
        parts = tasks_per_log or max(1, -(-2 * n_workers // len(paths)))
        n_tasks, logs = 0, {}
        for k, g in enumerate(grids):
            if g is None or k in errors:
                continue
            ranges = segment_ranges(g.n_samples, sett["nperseg"], sett["noverlap"], parts)
            if not ranges:
                errors[k] = (f"not analysed: {g.n_samples} grid samples hold no Welch segment of "
                             f"nperseg={sett['nperseg']}")
                continue
            futs = [c.submit(_task, paths[k], tuple(channels), fs, g.t0_ns, g.n_samples, g.stamp_offsets, rng, sett,
                             pure=False) for rng in ranges]
            n_tasks += len(futs)
            logs[k] = c.submit(_log_row, paths[k], bands, tuple(channels), fs, opts, *futs, pure=False)
        results = dict(zip(logs, c.gather(list(logs.values())))) if logs else {}
    finally:
        for o in owned:
            o.close()
    rows, good = [], []
    for k, p in enumerate(paths):
        n = grids[k].n_samples if grids[k] is not None else 0
        if k in results:
            sp, row = results[k]
            row = replace(row, n_samples=n, duration_s=n / fs)  # the log's grid, not only its whole segments
            if sp is None:
                errors[k] = row.error
            else:
                good.append(k)
        else:
            row = _failed_row(p, n, fs, bands, channels, errors[k])
        rows.append(row)
    if not good:
        raise none_left()
    per_log = {paths[k]: results[k][0] for k in good}
    merged = merge_spectra([results[k][0] for k in good])
    excluded = [p for k, p in enumerate(paths) if k not in good]
    warns = [f"{paths[k]}: left out of the merged spectra: {e}" for k, e in sorted(errors.items())]
    if resampled:
        warns.append(f"resampled onto the fleet's {fs:.6g} Hz (rate within {100 * RATE_TOLERANCE:g} %): "
                     + ", ".join(resampled))
    settings = dict(sett, fs=fs, channels=list(channels), bands_hz=[list(b) for b in bands], tasks=n_tasks,
                    workers=n_workers, input=input, excluded=excluded, warnings=warns,
                    **({"input_choice": choice} if choice else {}))
    return FleetResult(tuple(rows), per_log, merged, settings)
