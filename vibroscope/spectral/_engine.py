"""The one-pass cross-spectral engine.

All spectral estimates of :mod:`vibroscope.spectral` come from here: segments of every channel are
detrended and windowed in one compiled pass into a reused block, transformed once
(``scipy.fft.rfft``), and the products ``conj(X_i)·X_j`` of the channel pairs (upper triangle, or
the pairs with a reference channel) are accumulated by a compiled kernel tiled over frequency
(:mod:`vibroscope.spectral._kernels`, numba, loaded on the first pass). Working memory is
``O(n_pairs · n_freqs + n_channels · block · nfft)``, independent of the record length, and records
can be fed in pieces (:class:`CrossSpectralAccumulator`), so a log that does not fit in memory, or a
fleet of logs on Dask, is averaged exactly like one array.

Speed (10 channels × 2e6 samples, nperseg 4096, 50 % overlap; ``benchmarks/run.py --only-csd``):
the kernels release the GIL, so threads over segment ranges use every core. The pair kernel beats
a batched zgemm (``np.matmul`` over the frequencies, after the transpose it needs) from 4 to 64
channels (``benchmarks/scaling.py``), so there is no switch to BLAS.

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
from typing import Any, Literal, Sequence

import numpy as np
import scipy.fft
import scipy.signal

from vibroscope._checks import check_option  # re-exported: its old home

__all__ = ["CrossSpectralAccumulator", "check_option", "segment_settings"]

Detrend = Literal["constant", "linear", False]
Scaling = Literal["density", "spectrum"]
DType = Literal["float64", "float32"]

#: most segments transformed per batched FFT
_BLOCK = 64
#: bytes of the FFT input and output of one block (per thread): bounds the working memory
#: independently of the record length
_BLOCK_BYTES = 8 * 2**20
_NUMPY2 = int(np.__version__.split(".")[0]) >= 2  # np.fft.rfft(..., out=)


@dataclass(frozen=True, kw_only=True)
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

    Returns
    -------
    SegmentSettings
        The completed settings.

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
    return SegmentSettings(nperseg=nperseg, noverlap=noverlap, nfft=nfft, window=win, window_spec=window,
                           detrend=detrend)


def _flat_rows(buf: np.ndarray) -> tuple[np.ndarray, int]:
    """`buf` (C, n) as a C-contiguous 1-D read-only view of its memory and the row stride in
    elements (row c starts at ``c * stride``), without a copy when the rows have unit stride (any
    row-sliced or C-ordered array); otherwise (e.g. Fortran order) a C-ordered copy is made."""
    item = buf.itemsize
    if buf.strides[1] != item or buf.strides[0] < 0 or buf.strides[0] % item:
        buf = np.ascontiguousarray(buf)
    stride = buf.strides[0] // item if buf.shape[0] > 1 else 0
    span = (buf.shape[0] - 1) * stride + buf.shape[1]
    flat = np.lib.stride_tricks.as_strided(buf, shape=(span,), strides=(item,), writeable=False)
    return flat, int(stride)


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
    dtype : {'float64', 'float32'}, optional
        Precision of the segments and their FFTs; the products are always accumulated in float64.
        ``'float32'`` is up to ~1.4× faster and agrees with the float64 result to a relative
        error of 1e-7 to 1e-6 of the largest entry (single-precision rounding of the windowed
        segments and of the FFT, which grows like ``log2(nfft)``); a float32 record is read as is.
    references : sequence of int, optional
        Reference channels (positions): accumulate only the pairs with a reference channel, and
        the auto-spectra, ``C·R + C`` products instead of ``C(C+1)/2`` (SSI/OMA with reference
        sensors, FRFs with few inputs). The other off-diagonal entries of :meth:`result` are NaN
        (:attr:`computed`). Default: all pairs.

    Raises
    ------
    ValueError
        If `dtype` is unknown, or `references` are not distinct positions in ``[0, n_channels)``
        or are given with ``cross=False``.

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

    The pass, per block of segments (at most :data:`_BLOCK_BYTES` of FFT input and output, so the
    working memory does not grow with the record): one compiled (numba) pass per segment that
    detrends, windows and checks finiteness; ``scipy.fft.rfft`` of the block; a compiled kernel
    that adds ``conj(X_i)·X_j`` for the upper triangle of pairs, tiled over frequency so that the
    tile of spectra and of sums stays in cache. The kernels release the GIL, so threads over
    disjoint segment ranges (:func:`~vibroscope.spectral.csd_matrix` ``workers``) use all cores.

    References
    ----------
    .. [1] P. D. Welch, IEEE Trans. Audio Electroacoust. AU-15, 70–73, 1967.
    """

    def __init__(self, n_channels: int, fs: float, settings: SegmentSettings, *, cross: bool = True,
                 dtype: DType = "float64", references: Sequence[int] | None = None):
        self.n_channels = int(n_channels)
        self.fs = float(fs)
        self.settings = settings
        self.cross = bool(cross)
        check_option("dtype", dtype, ("float64", "float32"))
        self.dtype = dtype
        nf = settings.n_freqs
        n = self.n_channels
        ii, jj = np.triu_indices(n) if cross else (np.arange(n), np.arange(n))
        self.references: tuple[int, ...] | None = None
        if references is not None:
            if not cross:
                raise ValueError(f"{references=} needs cross=True (the auto-spectra have no reference channel)")
            refs = [int(r) for r in np.atleast_1d(np.asarray(references))]
            if not refs or any(not 0 <= r < n for r in refs) or len(set(refs)) != len(refs):
                raise ValueError(f"{references=} must be distinct channel positions in [0, {n}) (at least one)")
            self.references = tuple(refs)
            # the pairs with a reference channel, and every auto-spectrum: C·R + C products, not C²
            keep = np.isin(ii, refs) | np.isin(jj, refs) | (ii == jj)
            ii, jj = ii[keep], jj[keep]
        self._pairs = (ii.astype(np.int64), jj.astype(np.int64))
        # Σ_s conj(X_i,s) X_j,s of the pairs only (upper triangle / reference pairs / diagonal),
        # interleaved (real, imaginary): half the full Hermitian matrix, built only by result()
        self._pair_sum = np.zeros((ii.size, 2 * nf))
        self.n_segments = 0
        self._count = np.zeros((n, n), dtype=np.int64)
        self._tail = np.empty((n, 0))

    # -- feeding ---------------------------------------------------------------------------
    def update(self, x: np.ndarray) -> "CrossSpectralAccumulator":
        """Add the next piece of the record, shape (n_channels, n_samples_piece); returns self.

        Parameters
        ----------
        x : array_like, shape (n_channels, n_samples_piece)
            The samples following those already fed (any length; a partial segment is carried
            over to the next piece). float64 and float32 arrays are read in place (rows may be
            strided); other types are converted to float64.

        Returns
        -------
        CrossSpectralAccumulator
            Itself.

        Raises
        ------
        ValueError
            If `x` is not 2-D with ``n_channels`` rows.
        """
        x = np.asarray(x)
        if x.dtype not in (np.float64, np.float32):
            x = x.astype(float)
        if x.ndim != 2 or x.shape[0] != self.n_channels:
            raise ValueError(f"piece must have shape ({self.n_channels}, n), got {x.shape=}")
        st = self.settings
        nper, step = st.nperseg, st.step
        t = self._tail.shape[1]
        if t:
            # the segments that start in the carried-over tail: a short joined head (< 2 nperseg
            # samples), then the rest of the piece in place (the piece itself is never copied)
            head = np.concatenate([self._tail, x[:, :nper]], axis=1)
            n_h = 0 if head.shape[1] < nper else (head.shape[1] - nper) // step + 1
            if n_h:
                self._accumulate(head, n_h)
            if x.shape[1] <= nper:
                self._tail = head[:, n_h * step:].copy()
                return self
            x = x[:, n_h * step - t:]  # the next segment starts at n_h·step ≥ t in the joined record
        n = x.shape[1]
        n_seg = 0 if n < nper else (n - nper) // step + 1
        if n_seg:
            self._accumulate(x, n_seg)
        self._tail = x[:, n_seg * step:].astype(float)  # a copy (< nperseg samples)
        return self

    def reserve(self, n_seg: int) -> None:
        """Allocate the block buffers of a pass over `n_seg` segments now (a threaded pass
        reserves every thread's before starting them: its peak memory then does not depend on
        how the threads overlap).

        Parameters
        ----------
        n_seg : int
            Segments the next :meth:`add_segments` call will add.
        """
        self._buffers(self._block(int(n_seg)))

    def add_segments(self, buf: np.ndarray, n_seg: int) -> None:
        """Add the `n_seg` segments that start at ``0, step, ...`` in `buf`, with no carry-over
        to or from :meth:`update` (a contiguous range of whole segments of a record).

        Parameters
        ----------
        buf : ndarray, shape (n_channels, n_samples)
            ``n_samples >= (n_seg - 1) * step + nperseg``.
        n_seg : int
            Segments to add.
        """
        self._accumulate(buf, int(n_seg))

    def _block(self, n_seg: int) -> int:
        """Segments per block: the FFT input and output of one block within :data:`_BLOCK_BYTES`
        (at least ``n_pairs / (2 n_channels)``, at most :data:`_BLOCK` and `n_seg`)."""
        st = self.settings
        item = 4 if self.dtype == "float32" else 8
        per_seg = self.n_channels * (st.nfft * item + st.n_freqs * 2 * item)
        # each block reads and writes the pair sums (n_pairs × n_freqs): with many channels the
        # block grows past the byte budget so that this costs at most what the block's spectra do
        min_block = -(-self._pairs[0].size // (2 * self.n_channels))
        return int(min(n_seg, _BLOCK, max(min_block, _BLOCK_BYTES // per_seg)))

    def _buffers(self, nb_max: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The block buffers of the next pass (FFT input, finiteness flags, FFT output or None):
        those allocated ahead by the caller when large enough (the threaded pass allocates every
        thread's buffers before starting them, so its peak memory does not depend on how the
        threads happen to overlap), else new ones."""
        st = self.settings
        n_ch = self.n_channels
        got = getattr(self, "_bufs", None)
        if got is not None and got[0].shape[1] >= nb_max:
            return got
        ftype = np.float32 if self.dtype == "float32" else np.float64
        work = np.zeros((n_ch, nb_max, st.nfft), ftype)  # zero padding to nfft stays zero
        ok = np.empty((n_ch, nb_max), bool)
        # numpy ≥ 2 writes float64 FFTs into this flat block (a contiguous view for any block size)
        spec = np.empty(n_ch * nb_max * st.n_freqs, complex) if _NUMPY2 and ftype is np.float64 else None
        self._bufs = (work, ok, spec)
        return self._bufs

    def _accumulate(self, buf: np.ndarray, n_seg: int) -> None:
        """Add the `n_seg` segments that start at ``0, step, ...`` in `buf` (no carry-over); the
        block buffers are freed afterwards."""
        from vibroscope.spectral import _kernels  # numba: loaded on the first pass, not on import

        st = self.settings
        n_ch = self.n_channels
        nb_max = self._block(n_seg)
        work, ok, spec = self._buffers(nb_max)
        self._bufs = None  # freed with this pass (never pickled or kept between pieces)
        ii, jj = self._pairs
        acc = self._pair_sum
        ftile = _kernels.frequency_tile(ii.size)
        mode = {False: 0, "constant": 1, "linear": 2}[st.detrend]
        win = np.asarray(st.window, dtype=float)
        flat, row_stride = _flat_rows(buf)
        for b0 in range(0, n_seg, nb_max):
            nb = min(nb_max, n_seg - b0)
            w, okb = work[:, :nb], ok[:, :nb]
            # detrend × window in one pass per segment; a segment holding NaN/Inf is zeroed (it adds
            # nothing to any pair) and flagged, from the sums the detrend computes anyway
            _kernels.prepare_segments(flat, row_stride, b0, st.step, win, mode, w, okb)
            if spec is not None:  # numpy ≥ 2, float64: into the reused block (measured 1.2–1.3× faster
                # than scipy.fft here, and better on two threads)
                X = np.fft.rfft(w, axis=-1, out=spec[: n_ch * nb * st.n_freqs].reshape(n_ch, nb, st.n_freqs))
            else:  # float32 (numpy's float32 FFT is slower than scipy's), or numpy < 2
                X = scipy.fft.rfft(w, axis=-1)  # (n_ch, nb, n_freqs); float32 in, complex64 out
            _kernels.accumulate_pairs(X.view(X.real.dtype), ii, jj, acc, ftile)
            del X  # (scipy.fft) before the next block's FFT allocates its output
            if okb.all():
                self._count += nb
            else:
                okf = okb.astype(np.int64)
                self._count += okf @ okf.T
        self.n_segments += n_seg

    def _full(self, pair_scale: np.ndarray) -> np.ndarray:
        """The pair sums times `pair_scale` (n_pairs,) as the full matrix (n_freqs, C, C), Hermitian,
        real diagonal, NaN where not computed; or the auto-spectra (C, n_freqs) when not cross."""
        S = self._pair_sum.view(complex)  # (n_pairs, n_freqs)
        ii, jj = self._pairs
        if not self.cross:
            return S.real * pair_scale[:, None]
        n, nf = self.n_channels, self.settings.n_freqs
        out = np.empty((nf, n, n), complex) if self.references is None else np.full((nf, n, n), np.nan + 0j)
        for i0 in range(0, ii.size, 256):  # in slices: no temporary of the whole matrix
            sl = slice(i0, i0 + 256)
            v = (S[sl] * pair_scale[sl, None]).T
            out[:, ii[sl], jj[sl]] = v
            out[:, jj[sl], ii[sl]] = v.conj()
        d = np.arange(n)
        out[:, d, d] = out[:, d, d].real  # |X_i|² is real (the kernel's FMA leaves ~1e-16)
        return out

    @property
    def _sum(self) -> np.ndarray:
        """Unscaled sums as the full matrix (n_freqs, C, C) or the auto-spectra (C, n_freqs)."""
        return self._full(np.ones(self._pairs[0].size))

    def auto_sums(self) -> np.ndarray:
        """Each channel's unscaled auto-spectrum sums added over frequency.

        Returns
        -------
        ndarray, shape (n_channels,)
            0 exactly for a channel that is constant in every segment (read from the diagonal
            pairs, no full matrix).
        """
        ii, jj = self._pairs
        d = ii == jj
        out = np.zeros(self.n_channels)
        out[ii[d]] = self._pair_sum[d, 0::2].sum(axis=1)
        return out

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
            Itself.

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
            "references": (self.references, other.references),
            "dtype": (self.dtype, other.dtype),
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
        self._pair_sum += other._pair_sum
        self._count += other._count
        self.n_segments += other.n_segments
        return self

    # -- results ---------------------------------------------------------------------------
    @property
    def computed(self) -> np.ndarray:
        """Which entries ``(i, j)`` of the matrix are accumulated, bool, shape (n_channels, n_channels):
        all of them, or with `references` the rows and columns of the reference channels and the
        diagonal (the others are NaN in :meth:`result`)."""
        n = self.n_channels
        if self.references is None:
            return np.ones((n, n), bool)
        m = np.eye(n, dtype=bool)
        m[:, list(self.references)] = True
        m[list(self.references), :] = True
        return m

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

        Pairs (or, for auto-spectra, channels) with no valid segment (:attr:`n_averages` 0) are NaN,
        and so are, with `references`, the entries that were not accumulated (:attr:`computed`).

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
        # each pair normalised by its own number of valid segments (all equal without NaN/Inf);
        # a pair with none is NaN
        cnt = self._count[self._pairs].astype(float)
        with np.errstate(divide="ignore", invalid="ignore"):
            pair_scale = np.where(cnt > 0, scale / cnt, np.nan)
        out = self._full(pair_scale)
        fax = 0 if self.cross else -1
        sl = [slice(None)] * out.ndim
        last = None if self.settings.nfft % 2 else -1
        sl[fax] = slice(1, last)
        out[tuple(sl)] *= 2.0
        return out
