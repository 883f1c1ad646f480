"""The one-pass cross-spectral engine.

All spectral estimates of :mod:`vibroscope.spectral` come from here: segments of every channel are
detrended, windowed and transformed once (``scipy.fft.rfft`` into a reused block), and the products
``conj(X_i)·X_j`` of all channel pairs are accumulated with one batched matrix product per block of
segments. Working memory is ``O(n_channels² · n_freqs + n_channels · block · nperseg)``, independent
of the record length, and records can be fed in pieces (:class:`CrossSpectralAccumulator`), so a log
that does not fit in memory, or a fleet of logs on Dask, is averaged exactly like one array.

References
----------
.. [1] P. D. Welch, "The use of the fast Fourier transform for the estimation of power spectra: A
   method based on time averaging over short, modified periodograms", IEEE Trans. Audio
   Electroacoust. AU-15, 70–73, 1967.
.. [2] J. S. Bendat and A. G. Piersol, *Random Data: Analysis and Measurement Procedures*, 4th ed.,
   Wiley, 2010, ch. 11 (cross-spectral density estimates, window correction).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.fft
import scipy.signal

from vibroscope._checks import check_option  # re-exported: its old home

__all__ = ["CrossSpectralAccumulator", "check_option", "segment_settings"]

Detrend = Literal["constant", "linear", False]
Scaling = Literal["density", "spectrum"]

#: segments transformed per batched FFT; bounds working memory independently of record length
_BLOCK = 64


@dataclass(frozen=True)
class SegmentSettings:
    """Validated Welch segmenting settings (see :func:`segment_settings`)."""

    nperseg: int
    noverlap: int
    nfft: int
    window: np.ndarray
    window_spec: Any
    detrend: Any

    @property
    def step(self) -> int:
        """Hop between segment starts in samples."""
        return self.nperseg - self.noverlap

    @property
    def n_freqs(self) -> int:
        """Number of one-sided frequency bins ``nfft // 2 + 1``."""
        return self.nfft // 2 + 1


def segment_settings(
    n: int | None,
    *,
    nperseg: int | None,
    noverlap: int | None,
    window: Any,
    detrend: Any,
    nfft: int | None = None,
) -> SegmentSettings:
    """Validate and complete segmenting settings with scipy's defaults.

    Parameters
    ----------
    n : int or None
        Record length in samples (None when streaming: not checked against `nperseg`).
    nperseg : int or None
        Segment length; None gives scipy's default ``min(256, n)`` (or the window's length when
        `window` is an array).
    noverlap : int or None
        Overlap in samples; None gives ``nperseg // 2``.
    window : str, tuple or array_like
        Window spec for :func:`scipy.signal.get_window` (periodic, "fftbins") or the window itself.
    detrend : {'constant', 'linear', False}
        Per-segment detrending.
    nfft : int or None
        FFT length (zero padding); None gives `nperseg`.

    Raises
    ------
    ValueError
        If `nperseg` is not a positive whole number or exceeds the record length, `noverlap` is
        not in ``[0, nperseg)``, `nfft` is shorter than `nperseg`, or `detrend` is not an allowed
        option; the message names the setting and the remedy.
    """
    if nperseg is not None:
        if isinstance(nperseg, (bool, np.bool_)) or int(nperseg) != nperseg:
            raise ValueError(f"{nperseg=} must be a whole number of samples")
        if nperseg < 1:
            raise ValueError(f"{nperseg=} must be positive (a segment length in samples)")
    if isinstance(window, (str, tuple)):
        if nperseg is None:
            nperseg = 256 if n is None else min(256, n)
        if n is not None and nperseg > n:
            raise ValueError(f"{nperseg=} must not exceed the record length {n=}: use a shorter nperseg "
                             f"or a longer record")
        win = scipy.signal.get_window(window, int(nperseg), fftbins=True)
    else:
        win = np.asarray(window, dtype=float)
        if win.ndim != 1:
            raise ValueError(f"window must be 1-D, got {win.shape=}")
        if nperseg is None:
            nperseg = win.size
        if win.size != nperseg:
            raise ValueError(f"{win.size=} must equal {nperseg=}")
    nperseg = int(nperseg)
    if nperseg < 1:
        raise ValueError(f"{nperseg=} must be positive (a segment length in samples)")
    if n is not None and nperseg > n:
        raise ValueError(f"{nperseg=} must not exceed the record length {n=}: use a shorter nperseg "
                         f"or a longer record")
    if noverlap is not None and (isinstance(noverlap, (bool, np.bool_)) or int(noverlap) != noverlap):
        raise ValueError(f"{noverlap=} must be a whole number of samples")
    noverlap = nperseg // 2 if noverlap is None else int(noverlap)
    if not 0 <= noverlap < nperseg:
        raise ValueError(f"{noverlap=} must be in [0, {nperseg=}): use a smaller noverlap "
                         f"(default nperseg // 2)")
    nfft = nperseg if nfft is None else int(nfft)
    if nfft < nperseg:
        raise ValueError(f"{nfft=} must be at least {nperseg=}")
    check_option("detrend", detrend, ("constant", "linear", False))
    win.flags.writeable = False
    return SegmentSettings(nperseg, noverlap, nfft, win, window, detrend)


class CrossSpectralAccumulator:
    """Streaming accumulator of Welch cross-spectra for all channel pairs.

    Feed the record in any number of pieces with :meth:`update`; segments straddling two pieces are
    handled exactly (the last ``nperseg - 1`` samples are carried over), so the result equals a
    single pass over the concatenated record. Accumulators over disjoint records (a fleet of logs,
    Dask partitions) combine with :meth:`merge`.

    Parameters
    ----------
    n_channels : int
        Number of channels (rows of every piece).
    fs : float
        Sampling frequency in Hz.
    settings : SegmentSettings
        From :func:`segment_settings`.
    cross : bool, optional
        Accumulate the full Hermitian matrix ``conj(X_i)·X_j`` (True) or only the auto-spectra
        ``|X_i|²`` (False, cheaper, for PSDs).

    Notes
    -----
    For segment ``s`` of channel ``i``, ``X_i,s = rfft(w · detrend(x_i,s), nfft)``. The accumulator
    holds ``S[f, i, j] = Σ_s conj(X_i,s[f]) · X_j,s[f]`` and the segment count; :meth:`result`
    scales by ``1 / (fs Σ w²)`` (density) or ``1 / (Σ w)²`` (spectrum), doubles all bins but DC
    (and Nyquist for even `nfft`), and divides by the count — scipy's ``csd`` conventions [1]_.

    Missing samples: a segment of channel ``i`` that holds a NaN or ±Inf is skipped for every pair
    with ``i`` (its transform is set to zero, so it adds nothing), and each pair keeps its own
    count ``K_ij`` of segments in which both channels are finite (:attr:`n_averages`);
    ``G_ij = S_ij / K_ij`` is then exactly Welch's estimate over the segments valid for that pair.
    Without NaN/Inf the pass is unchanged (finiteness is read from the per-segment mean that the
    constant detrend computes anyway) and every ``K_ij`` equals :attr:`n_segments`.

    References
    ----------
    .. [1] P. D. Welch, IEEE Trans. Audio Electroacoust. AU-15, 70–73, 1967.
    """

    def __init__(self, n_channels: int, fs: float, settings: SegmentSettings, *, cross: bool = True):
        self.n_channels = int(n_channels)
        self.fs = float(fs)
        self.settings = settings
        self.cross = bool(cross)
        nf = settings.n_freqs
        shape = (nf, self.n_channels, self.n_channels) if cross else (self.n_channels, nf)
        self._sum = np.zeros(shape, dtype=complex if cross else float)
        self.n_segments = 0
        self._count = np.zeros((self.n_channels, self.n_channels), dtype=np.int64)
        self._tail = np.empty((self.n_channels, 0))

    # -- feeding ---------------------------------------------------------------------------
    def update(self, x: np.ndarray) -> "CrossSpectralAccumulator":
        """Add the next piece of the record, shape (n_channels, n_samples_piece); returns self.

        Parameters
        ----------
        x : array_like, shape (n_channels, n_samples_piece)
            The samples following those already fed (any length; a partial segment is carried
            over to the next piece).

        Returns
        -------
        CrossSpectralAccumulator
            self.

        Raises
        ------
        ValueError
            If `x` is not 2-D with ``n_channels`` rows.
        """
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[0] != self.n_channels:
            raise ValueError(f"piece must have shape ({self.n_channels}, n), got {x.shape=}")
        buf = np.concatenate([self._tail, x], axis=1) if self._tail.shape[1] else x
        st = self.settings
        n = buf.shape[1]
        n_seg = 0 if n < st.nperseg else (n - st.nperseg) // st.step + 1
        if n_seg:
            self._accumulate(buf, n_seg)
        start_next = n_seg * st.step
        self._tail = buf[:, start_next:].copy()
        return self

    def _accumulate(self, buf: np.ndarray, n_seg: int) -> None:
        st = self.settings
        # strided view: (n_channels, n_seg, nperseg), no copy
        segs = np.lib.stride_tricks.sliding_window_view(buf, st.nperseg, axis=1)[:, :: st.step][:, :n_seg]
        work = np.empty((self.n_channels, min(_BLOCK, n_seg), st.nperseg))
        for b0 in range(0, n_seg, _BLOCK):
            blk = segs[:, b0 : b0 + _BLOCK]
            nb = blk.shape[1]
            w = work[:, :nb]
            # finiteness of each (channel, segment) from a per-segment reduction: the mean that the
            # constant detrend needs anyway, so the NaN-free path does no extra pass
            with np.errstate(invalid="ignore", over="ignore"):  # Inf - Inf in a segment to be skipped
                if st.detrend == "constant":
                    mean = blk.mean(axis=-1, keepdims=True)
                    ok = np.isfinite(mean[..., 0])
                    np.subtract(blk, mean, out=w)
                else:
                    ok = np.isfinite(blk.sum(axis=-1))
                    w[...] = blk
            clean = bool(ok.all())
            if not clean:
                w[~ok] = 0.0  # a segment touching NaN/Inf contributes nothing to any pair
            if st.detrend == "linear":
                w[...] = scipy.signal.detrend(w, type="linear", axis=-1)
            w *= st.window
            X = scipy.fft.rfft(w, n=st.nfft, axis=-1)  # (n_ch, nb, nf)
            if self.cross:
                Xf = np.ascontiguousarray(X.transpose(2, 0, 1))  # (nf, n_ch, nb)
                self._sum += np.matmul(Xf.conj(), Xf.transpose(0, 2, 1))
            else:
                self._sum += (X.real**2 + X.imag**2).sum(axis=1)
            if clean:
                self._count += nb
            else:
                okf = ok.astype(np.int64)
                self._count += okf @ okf.T
        self.n_segments += n_seg

    def merge(self, other: "CrossSpectralAccumulator") -> "CrossSpectralAccumulator":
        """Add the segment sums of an accumulator over another (disjoint) record; returns self.

        Parameters
        ----------
        other : CrossSpectralAccumulator
            An accumulator with the same settings; its carried-over partial segment is not
            added (segments never straddle two records).

        Returns
        -------
        CrossSpectralAccumulator
            self.

        Raises
        ------
        ValueError
            If the two differ in a setting that changes the sums: ``n_channels``, ``fs``, ``cross``
            (the mode), ``nperseg``, ``noverlap``, ``nfft``, ``window`` or ``detrend``; the message
            names the setting.
        """
        a, b = self.settings, other.settings
        pairs = {
            "n_channels": (self.n_channels, other.n_channels),
            "fs": (self.fs, other.fs),
            "cross": (self.cross, other.cross),
            "nperseg": (a.nperseg, b.nperseg),
            "noverlap": (a.noverlap, b.noverlap),
            "nfft": (a.nfft, b.nfft),
            "detrend": (a.detrend, b.detrend),
        }
        for name, (mine, theirs) in pairs.items():
            if mine != theirs:
                raise ValueError(f"cannot merge accumulators with different {name}: {mine!r} and {theirs!r}")
        if not np.array_equal(a.window, b.window):
            mine, theirs = (w if isinstance(w, (str, tuple)) else "custom" for w in (a.window_spec, b.window_spec))
            raise ValueError(f"cannot merge accumulators with different window: {mine!r} and {theirs!r}")
        self._sum += other._sum
        self._count += other._count
        self.n_segments += other.n_segments
        return self

    # -- results ---------------------------------------------------------------------------
    @property
    def n_averages(self) -> np.ndarray:
        """Segments averaged per channel pair (both channels finite over the segment), int, shape
        (n_channels, n_channels); the diagonal is the count per channel."""
        return self._count.copy()

    def frequencies(self) -> np.ndarray:
        """One-sided frequency axis in Hz, shape (nfft // 2 + 1,)."""
        return scipy.fft.rfftfreq(self.settings.nfft, 1.0 / self.fs)

    def result(self, scaling: Scaling = "density") -> np.ndarray:
        """Scaled, averaged one-sided spectra.

        Parameters
        ----------
        scaling : {'density', 'spectrum'}, optional
            ``1 / (fs Σw²)`` per segment, unit²/Hz (default), or ``1 / (Σw)²``, unit².

        Returns
        -------
        ndarray
            ``G[f, i, j]`` complex, shape (n_freqs, n_channels, n_channels) when ``cross``; else the
            auto-spectra, shape (n_channels, n_freqs). Units: unit_i·unit_j/Hz ('density') or
            unit_i·unit_j ('spectrum').

        Pairs (or, for auto-spectra, channels) with no valid segment (:attr:`n_averages` 0) are NaN.

        Raises
        ------
        ValueError
            If no complete segment has been accumulated, or `scaling` is unknown.
        """
        check_option("scaling", scaling, ("density", "spectrum"))
        if self.n_segments == 0:
            raise ValueError(f"no complete segment of nperseg={self.settings.nperseg} samples was accumulated")
        w = self.settings.window
        scale = 1.0 / (self.fs * np.sum(w * w)) if scaling == "density" else 1.0 / np.sum(w) ** 2
        if np.all(self._count == self.n_segments):
            out = self._sum * (scale / self.n_segments)
        else:  # each pair normalised by its own number of valid segments
            cnt = self._count.astype(float) if self.cross else np.diag(self._count).astype(float)[:, None]
            with np.errstate(divide="ignore", invalid="ignore"):
                out = self._sum * (scale / cnt)
            if self.cross:
                out[:, self._count == 0] = np.nan
            else:
                out[np.diag(self._count) == 0] = np.nan
        fax = 0 if self.cross else -1
        sl = [slice(None)] * out.ndim
        last = None if self.settings.nfft % 2 else -1
        sl[fax] = slice(1, last)
        out[tuple(sl)] *= 2.0
        return out
