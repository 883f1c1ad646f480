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

Dask is imported here only when :func:`analyse_fleet` runs (the ``[dask]`` extra).
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from vibroscope.stream import LogSpectra, merge_spectra, segment_ranges, stream_settings

__all__ = ["FleetRow", "FleetResult", "analyse_fleet", "local_cluster", "octave_bands", "band_rms", "WORKER_ENV"]


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


@dataclass(frozen=True)
class FleetRow:
    """One log of the fleet table.

    Attributes
    ----------
    log : str
        The log's path.
    n_samples : int
        Grid samples analysed.
    duration_s : float
        ``n_samples / fs``.
    frequencies_hz, damping_ratios : tuple of float
        The modes identified from the log's spectra.
    bands_hz : tuple of (float, float)
        The bands of `rms`.
    channels : tuple of str
        The channels of `rms`.
    rms : tuple of tuple of float
        ``rms[c][b]``: RMS of channel c in band b (the channel's unit).
    error : str
        Why the modes could not be identified (empty when they were).
    """

    log: str
    n_samples: int
    duration_s: float
    frequencies_hz: tuple
    damping_ratios: tuple
    bands_hz: tuple
    channels: tuple
    rms: tuple
    error: str = ""

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
                          for f, z in zip(self.frequencies_hz, self.damping_ratios)],
                "rms": {c: {f"{lo:.4g}-{hi:.4g}Hz": num(v) for (lo, hi), v in zip(self.bands_hz, r)}
                        for c, r in zip(self.channels, self.rms)},
                "error": self.error}


@dataclass(frozen=True, eq=False)
class FleetResult:
    """What :func:`analyse_fleet` found.

    Attributes
    ----------
    rows : tuple of FleetRow
        The fleet table, one row per log, in the order given.
    per_log : dict of str to LogSpectra
        Each log's accumulated spectra (exactly one pass over the log).
    merged : LogSpectra
        All logs' sums merged (every segment of every log averaged once).
    settings : dict
        Welch settings, rate, channels, bands, tasks and workers.
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
            then per band ``rms_<lo>-<hi>Hz``: the largest channel RMS in the band, and
            ``error``.
        """
        out = []
        for r in self.rows:
            d = {"log": r.log, "n_samples": r.n_samples, "duration_s": f"{r.duration_s:.6g}",
                 "modes_hz": ";".join(f"{f:.6g}" for f in r.frequencies_hz),
                 "damping": ";".join(f"{z:.4g}" for z in r.damping_ratios)}
            rms = np.array(r.rms, float).reshape(len(r.channels), len(r.bands_hz))
            for k, (lo, hi) in enumerate(r.bands_hz):
                col = rms[:, k]
                d[f"rms_{lo:.4g}-{hi:.4g}Hz"] = f"{np.nanmax(col):.6g}" if np.isfinite(col).any() else ""
            d["error"] = r.error
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
            ``n_samples``, ``n_segments``, ``psd_peak_hz`` per channel).
        """
        G = self.merged.csd()
        P = G.psd().values
        f = G.frequencies
        peaks = {c: float(f[1 + int(np.nanargmax(p[1:]))]) for c, p in zip(G.channels, P)}
        sett = {k: (v if isinstance(v, (int, float, str, type(None))) else str(v)) for k, v in self.settings.items()}
        return {"logs": [r.to_dict() for r in self.rows], "settings": sett,
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
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=2))
        return path


def _task(path: str, channels: tuple, fs: float, t0_ns: int, n_samples: int, samples: tuple,
          settings: dict) -> LogSpectra:
    """One Dask task: accumulate grid samples `samples` of the log at `path` (runs on a worker)."""
    from vibroscope.stream import accumulate_log

    return accumulate_log(path, channels, fs=fs, t0_ns=t0_ns, n_samples=n_samples, samples=samples, **settings)


def _log_row(path: str, bands: tuple, channels: tuple, fs: float, opts: dict,
             *parts: LogSpectra) -> tuple[LogSpectra, FleetRow]:
    """One Dask task per log, after its range tasks: merge them and fill its row of the fleet table
    (band RMS and modes), so that the per-log identification runs on the workers, not the client."""
    from vibroscope.stream import analyse_stream

    sp = merge_spectra(list(parts))
    G = sp.csd()
    P = G.psd().values
    rms = band_rms(G.frequencies, P, bands)
    try:
        an = analyse_stream(sp, **opts)
        f_n, z, err = tuple(an.modal.natural_frequencies.tolist()), tuple(an.modal.damping_ratios.tolist()), ""
    except ValueError as exc:
        f_n, z, err = (), (), str(exc)
    return sp, FleetRow(path, sp.samples, sp.samples / fs, f_n, z, bands, tuple(channels),
                        tuple(tuple(r) for r in rms.tolist()), err)


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
                  fmax: float | None = None) -> FleetResult:
    """Spectra, modes and band RMS of many logs, the accumulation spread over a Dask cluster.

    Parameters
    ----------
    paths : sequence of str or Path
        The MCAP logs (the workers read them at these paths).
    client : dask.distributed.Client or str, optional
        A client, or a scheduler address (``"tcp://host:8786"``); default
        :func:`local_cluster` (one single-threaded worker process per core, closed at the end).
    channels : sequence of str, optional
        Message paths, the same in every log; default the Imu ``linear_acceleration`` fields of
        the first log (with `input` first when given).
    input : str, optional
        The force channel, for FRFs and LSCF per log.
    fs : float, optional
        Grid rate in Hz; default the first log's. Every log must have it (else ValueError).
    nperseg : int, optional
        Welch segment length for all logs; default :func:`vibroscope.stream.stream_settings` of
        the shortest log.
    window : str, optional
        Welch window; default Hann.
    bands : sequence of (float, float), optional
        Bands (Hz) for the RMS; default :func:`octave_bands`.
    tasks_per_log : int, optional
        Ranges each log is split into; default enough for two tasks per worker over the fleet.
    method : {'auto', 'lscf', 'peak', 'fdd', 'efdd'}, optional
        Identification per log (:func:`vibroscope.stream.analyse_stream`).
    fmin, fmax : float, optional
        Band (Hz) searched for modes; default from each log's spectra.

    Returns
    -------
    FleetResult

    Raises
    ------
    ValueError
        If `paths` is empty, or the logs differ in rate.
    LogFormatError, ChannelError
        If a log or a channel cannot be read (named).
    ImportError
        If ``dask.distributed`` is not installed (the ``[dask]`` extra).
    """
    from vibroscope.io.blocks import open_grid

    paths = [str(p) for p in paths]
    if not paths:
        raise ValueError("no logs given")
    fs_given = fs  # every log goes onto this rate when given
    first = open_grid(paths[0], channels, fs=fs)
    if channels is None and input is not None:
        channels = [input] + [c for c in first.channels if c != input]
        first = open_grid(paths[0], channels, fs=fs)
    channels = first.channels
    fs = first.fs
    grids = [first] + [open_grid(p, channels, fs=fs_given) for p in paths[1:]]
    for g in grids[1:]:
        if abs(g.fs - fs) > 1e-9 * fs:
            raise ValueError(f"{g.path}: rate {g.fs:.9g} Hz differs from {fs:.9g} Hz of {paths[0]}: analyse the logs "
                             f"of one rate together (or give fs= (--fs) to resample them all)")
        g.fs = fs
    sett = stream_settings(min(g.n_samples for g in grids), fs, nperseg=nperseg, window=window)
    df = fs / sett["nfft"]
    bands = tuple(tuple(map(float, b)) for b in (bands if bands is not None else octave_bands(fs, df)))
    opts = dict(input=input, method=method, fmin=fmin, fmax=fmax)
    c, owned = _client(client)
    try:
        n_workers = max(1, len(c.scheduler_info().get("workers", {})) or 1)
        parts = tasks_per_log or max(1, -(-2 * n_workers // len(paths)))
        n_tasks, logs = 0, []
        for g in grids:
            ranges = [c.submit(_task, str(g.path), tuple(channels), fs, g.t0_ns, g.n_samples, rng, sett, pure=False)
                      for rng in segment_ranges(g.n_samples, sett["nperseg"], sett["noverlap"], parts)]
            n_tasks += len(ranges)
            logs.append(c.submit(_log_row, str(g.path), bands, tuple(channels), fs, opts, *ranges, pure=False))
        results = c.gather(logs)
    finally:
        for o in owned:
            o.close()
    per_log = {p: sp for p, (sp, _) in zip(paths, results)}
    rows = [row for _, row in results]
    merged = merge_spectra([per_log[p] for p in paths])
    settings = dict(sett, fs=fs, channels=list(channels), bands_hz=[list(b) for b in bands], tasks=n_tasks,
                    workers=n_workers, input=input)
    return FleetResult(tuple(rows), per_log, merged, settings)
