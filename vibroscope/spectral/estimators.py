"""Spectral estimators: Welch PSD, the cross-spectral matrix, amplitude spectrum, FRF (H1, H2, Hv),
ordinary and multiple coherence, spectrogram.

Conventions are scipy's (``scipy.signal.welch/csd/coherence``): ``Pxy = conj(X)·Y``, one-sided and
doubled, ``scaling='density'`` (unit²/Hz) or ``'spectrum'`` (unit²), periodic Hann window by default,
``noverlap = nperseg // 2``, per-segment ``detrend='constant'``.
"""

from __future__ import annotations

import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Literal, Sequence

import numpy as np
import scipy.fft
import scipy.signal

from vibroscope._checks import check_option
from vibroscope.signals import Signals
from vibroscope.spectral._engine import CrossSpectralAccumulator, segment_settings
from vibroscope.spectral._results import (
    FRF,
    Coherence,
    CrossSpectralMatrix,
    MultipleCoherence,
    Spectrogram,
    Spectrum,
)
from vibroscope.spectral._results import channel_index
from vibroscope.spectral._results import power_units as _power_units
from vibroscope.spectral.kinds import FRF_KIND_TABLE, FRF_KINDS, kind_of_response_unit

__all__ = [
    "welch",
    "csd_matrix",
    "amplitude_spectrum",
    "frf",
    "coherence",
    "multiple_coherence",
    "spectrogram",
    "frf_kind",
    "MIN_AVERAGES",
    "FewAveragesWarning",
]

#: fewer valid segments than this for a channel pair, after segments touching NaN/Inf were
#: skipped, gives a :class:`FewAveragesWarning` (the relative standard deviation of a Welch
#: auto-spectrum is about ``1/sqrt(K)``: 35 % at K = 8); none at all is a ValueError
MIN_AVERAGES = 8


class FewAveragesWarning(UserWarning):
    """Few segments remain for a channel pair after skipping those with missing samples."""

Channel = str | int

_WELCH_PARAMS = """fs : float, optional
        Sampling frequency in Hz (taken from `x` when it is a :class:`~vibroscope.Signals`;
        default 1.0 for an array).
    nperseg : int, optional
        Segment length in samples; default ``min(256, n_samples)`` as scipy.
    noverlap : int, optional
        Overlap in samples; default ``nperseg // 2``.
    window : str, tuple or array_like, optional
        Window (scipy.signal.get_window spec, periodic) or its samples; default ``'hann'``.
    detrend : {'constant', 'linear', False}, optional
        Per-segment detrending; default ``'constant'``.
    nfft : int, optional
        FFT length (zero padding); default `nperseg`."""


def _fill_doc(fn):
    """Substitute the shared Welch parameter block into `fn`'s docstring (scipy's doccer idea)."""
    fn.__doc__ = fn.__doc__.replace("{welch_params}", _WELCH_PARAMS)
    return fn


def unpack_signals(x: Signals | np.ndarray, fs: float | None, *,
                   keep_float32: bool = False) -> tuple[np.ndarray, float, tuple, tuple]:
    """(data (n_ch, n), fs, channels, units) from Signals or an array (1-D = one channel); a float32
    array stays float32 (not copied) with `keep_float32`."""
    if isinstance(x, Signals):
        if fs is not None and float(fs) != x.fs:
            raise ValueError(f"{fs=} contradicts the Signals' fs={x.fs}")
        return x.data, x.fs, x.channels, x.units
    a = np.asarray(x)
    if np.iscomplexobj(a):
        raise TypeError(f"x must be real (got dtype {a.dtype}): pass the real and imaginary parts as "
                        f"separate channels, or np.real(x) if the imaginary part is noise")
    if not (keep_float32 and a.dtype == np.float32):
        a = np.asarray(a, dtype=float)
    if a.ndim == 1:
        a = a[np.newaxis]
    if a.ndim != 2:
        raise ValueError(f"x must be 1-D or 2-D (n_channels, n_samples), got {a.shape=}")
    fs = 1.0 if fs is None else float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"{fs=} must be a positive sampling frequency in Hz")
    return a, fs, tuple(str(i) for i in range(a.shape[0])), ("",) * a.shape[0]


#: fewest segments per worker thread: below this a thread costs more than it saves
_MIN_SEGMENTS_PER_WORKER = 32


def _n_workers(workers: int | None, n_seg: int) -> int:
    """Threads for `n_seg` segments: `workers` (None: the usable cores), bounded by the segments."""
    if workers is None:
        try:
            workers = len(os.sched_getaffinity(0))
        except AttributeError:  # not on Linux
            workers = os.cpu_count() or 1
    elif isinstance(workers, (bool, np.bool_)) or int(workers) != workers or workers < 1:
        raise ValueError(f"{workers=} must be a positive whole number of threads, or None (all usable cores)")
    return int(max(1, min(int(workers), n_seg // _MIN_SEGMENTS_PER_WORKER)))


def _accumulate(data, fs, st, *, cross: bool, workers: int | None, dtype: str = "float64",
                references=None) -> CrossSpectralAccumulator:
    n_ch, n = data.shape
    n_seg = (n - st.nperseg) // st.step + 1
    workers = _n_workers(workers, n_seg)
    kw = dict(cross=cross, dtype=dtype, references=references)
    if workers == 1:
        return CrossSpectralAccumulator(n_ch, fs, st, **kw).update(data)
    # one contiguous range of whole segments per thread, each read with its own overlap (the
    # kernels, numba and the FFT, release the GIL); a static split keeps the result deterministic
    # (handing out chunks on demand measured no faster on a busy machine, and sums in a varying order)
    bounds = np.linspace(0, n_seg, workers + 1).astype(int)
    accs = [CrossSpectralAccumulator(n_ch, fs, st, **kw) for _ in range(workers)]
    for k, acc in enumerate(accs):  # block buffers allocated here: a peak independent of the threads' timing
        acc.reserve(int(bounds[k + 1] - bounds[k]))

    def part(k: int) -> None:
        s0, s1 = int(bounds[k]), int(bounds[k + 1])
        accs[k].add_segments(data[:, s0 * st.step : (s1 - 1) * st.step + st.nperseg], s1 - s0)

    with ThreadPoolExecutor(workers) as pool:
        list(pool.map(part, range(workers)))
    for p in accs[1:]:
        accs[0].merge(p)
    return accs[0]


def settings_dict(fs, st, n_avg, n_segments=None) -> dict:
    """The ``settings`` a spectral result carries.

    Parameters
    ----------
    fs : float
        Sampling frequency in Hz.
    st : SegmentSettings
        From :func:`vibroscope.spectral.segment_settings`.
    n_avg : int
        Segments averaged (the fewest over the channels or pairs).
    n_segments : int, optional
        Segments in the record; stored as ``n_segments`` when it differs from `n_avg`.

    Returns
    -------
    dict
        ``fs``, ``nperseg``, ``noverlap``, ``nfft``, ``window`` (``"custom"`` for an array),
        ``detrend``, ``n_averages`` and maybe ``n_segments``.
    """
    win = st.window_spec if isinstance(st.window_spec, (str, tuple)) else "custom"
    out = dict(fs=fs, nperseg=st.nperseg, noverlap=st.noverlap, nfft=st.nfft, window=win,
               detrend=st.detrend, n_averages=n_avg)
    if n_segments is not None and n_segments != n_avg:
        out["n_segments"] = n_segments
    return out


def check_averages(acc: CrossSpectralAccumulator, channels: Sequence[str], *, cross: bool) -> np.ndarray:
    """Valid segments per pair (``cross``) or per channel; raise when one has none, warn when few.

    Parameters
    ----------
    acc : CrossSpectralAccumulator
        The accumulator after the record.
    channels : sequence of str
        Channel names (for the messages).
    cross : bool
        Count per pair (shape (n, n)) rather than per channel (shape (n,)).

    Returns
    -------
    ndarray of int
        The counts, shape (n, n) or (n,).

    Raises
    ------
    ValueError
        Naming the channel(s) with no segment free of NaN/Inf.

    Warns
    -----
    FewAveragesWarning
        When segments were skipped and fewer than :data:`MIN_AVERAGES` remain for a pair.
    """
    cnt = acc.n_averages
    if not cross:
        cnt = np.diag(cnt).copy()
    total = acc.n_segments
    if np.all(cnt == total):
        return cnt
    nper = acc.settings.nperseg
    diag = np.diag(acc.n_averages)
    for i in range(len(channels)):
        if diag[i] == 0:
            raise ValueError(
                f"channel {channels[i]!r} has no segment of nperseg={nper} samples free of NaN/Inf "
                f"(all {total} segments touch a missing sample): use a shorter nperseg, or drop the channel")
    if cross:
        zi, zj = np.nonzero(np.triu((cnt == 0) & acc.computed, 1))
        if zi.size:
            i, j = int(zi[0]), int(zj[0])
            raise ValueError(
                f"channels {channels[i]!r} and {channels[j]!r} have no common segment of nperseg={nper} "
                f"samples free of NaN/Inf (their gaps alternate): use a shorter nperseg")
    few = np.argwhere(np.triu((cnt < MIN_AVERAGES) & acc.computed)) if cross else np.argwhere(cnt < MIN_AVERAGES)
    if few.size:
        k = few[0]
        what = (f"channel {channels[k[0]]!r}" if (not cross or k[0] == k[1])
                else f"channels {channels[k[0]]!r} and {channels[k[1]]!r}")
        kk = int(cnt[tuple(k)])
        warnings.warn(f"only {kk} averages remain for {what} after skipping segments with NaN/Inf "
                      f"({total - kk} of {total} skipped): the spectra have a high variance (about "
                      f"{100 / np.sqrt(kk):.0f} %); use a shorter nperseg", FewAveragesWarning, stacklevel=4)
    return cnt


def _welch_pass(x, fs, nperseg, noverlap, window, detrend, nfft, scaling, workers, *, cross: bool,
                dtype: str = "float64", references=None):
    """Validate, then one pass of the engine: (accumulator, channels, units, settings dict, counts)."""
    check_option("dtype", dtype, ("float64", "float32"))
    data, fs, channels, units = unpack_signals(x, fs, keep_float32=dtype == "float32")
    check_option("scaling", scaling, ("density", "spectrum"))
    st = segment_settings(data.shape[1], nperseg=nperseg, noverlap=noverlap, window=window,
                          detrend=detrend, nfft=nfft)
    ref_idx = None
    if references is not None:
        if isinstance(references, (str, int, np.integer)):
            references = [references]
        ref_idx = list(dict.fromkeys(channel_index(channels, r) for r in references))  # unique, in order
    acc = _accumulate(data, fs, st, cross=cross, workers=workers, dtype=dtype, references=ref_idx)
    cnt = check_averages(acc, channels, cross=cross)
    settings = settings_dict(fs, st, int(cnt.min()), acc.n_segments)
    if dtype != "float64":
        settings["dtype"] = dtype
    if ref_idx is not None:
        settings["references"] = tuple(channels[i] for i in ref_idx)
    return acc, channels, units, settings, cnt


@_fill_doc
def csd_matrix(
    x: Signals | np.ndarray,
    fs: float | None = None,
    *,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple | np.ndarray = "hann",
    detrend: Literal["constant", "linear", False] = "constant",
    nfft: int | None = None,
    scaling: Literal["density", "spectrum"] = "density",
    workers: int | None = None,
    dtype: Literal["float64", "float32"] = "float64",
    references: Sequence[Channel] | Channel | None = None,
) -> CrossSpectralMatrix:
    """Cross-spectral matrix of all channel pairs by Welch's method, in one pass.

    Parameters
    ----------
    x : Signals or array_like, shape (n_channels, n_samples)
        The record. With an array, channels are named ``"0"``, ``"1"``, ...
    {welch_params}
    scaling : {'density', 'spectrum'}, optional
        unit²/Hz (default) or unit².
    workers : int, optional
        Threads splitting the segments (the compiled kernels and the FFT release the GIL); default
        None: the usable cores (``os.sched_getaffinity``), at most one per 32 segments. The result
        does not depend on it beyond rounding (~1e-16), and is the same on every run for a given
        number of threads. On a machine whose cores are busy with other work, one thread can be
        faster (measured 0.7–0.9× with two threads under a load of 2–4 on two cores; 1.8–1.9×
        when idle).
    dtype : {'float64', 'float32'}, optional
        Precision of the segments and FFTs (the sums are float64): ``'float32'`` is faster and
        agrees with float64 to a relative error of about 1e-6 of the largest entry; a float32
        array is then read without a float64 copy. Default ``'float64'`` (equal to scipy to
        ~1e-15).
    references : channel or sequence of channels, optional
        Reference channels (names or positions): compute only their rows and columns of `G` and
        the diagonal, ``C·R + C`` products instead of ``C(C+1)/2`` — enough for SSI/OMA with
        reference sensors and for :func:`frf` with these channels as inputs. The other
        off-diagonal entries are NaN; ``settings['references']`` names the channels. Default: all.

    Returns
    -------
    CrossSpectralMatrix
        ``G[f, i, j]`` with ``G[:, i, j] == scipy.signal.csd(x[i], x[j], ...)[1]``.

    Raises
    ------
    TypeError
        If `x` is complex (it is never cut silently to its real part).
    ValueError
        If `fs` or `nperseg` is not positive, `nperseg` exceeds the record length, `noverlap` ∉
        [0, nperseg), an option is unknown, or a channel (pair) has no segment free of NaN/Inf;
        the message names the setting or channel and the remedy.

    Warns
    -----
    FewAveragesWarning
        When segments were skipped for missing samples and fewer than :data:`MIN_AVERAGES` (8)
        remain for a pair.

    See Also
    --------
    welch : The diagonal only (power spectral densities), one channel at a time.
    frf : H1, H2 or Hv from this matrix.
    coherence : Ordinary coherence from this matrix.
    vibroscope.modal.fdd : Output-only modes from this matrix.

    Notes
    -----
    With segments ``x_s`` of length N, window w and ``X_i,s = FFT(w·x_i,s)``:
    ``G_ij(f_k) = (2 / (K fs Σw²)) Σ_s conj(X_i,s(f_k)) X_j,s(f_k)`` for ``0 < f_k < fs/2`` (no
    doubling at DC and Nyquist); ``scaling='spectrum'`` uses ``(Σw)²`` in place of ``fs Σw²``
    (Welch 1967; Bendat & Piersol 2010, §11.5). Every segment is transformed once for all pairs.

    Missing samples: a segment in which channel i or j holds a NaN or ±Inf is left out of
    ``G_ij``, and K is that pair's own count of valid segments (``n_averages[i, j]`` of the
    result); ``G[:, i, j]`` then equals ``scipy.signal.csd`` over those segments only. No sample
    is interpolated. With unequal counts the entries come from different segment sets.

    References
    ----------
    .. [1] P. D. Welch, IEEE Trans. Audio Electroacoust. AU-15, 70–73, 1967.
    .. [2] J. S. Bendat and A. G. Piersol, *Random Data*, 4th ed., Wiley, 2010.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> x = rng.standard_normal((2, 100_000))
    >>> G = csd_matrix(x, fs=1000.0, nperseg=1000)
    >>> round(float(G.G[1:-1, 0, 0].real.mean()), 4)  # white noise of unit variance: 2/fs per Hz
    0.002
    """
    acc, channels, units, settings, cnt = _welch_pass(x, fs, nperseg, noverlap, window, detrend, nfft, scaling,
                                                      workers, cross=True, dtype=dtype, references=references)
    return CrossSpectralMatrix(frequencies=acc.frequencies(), G=acc.result(scaling), channels=channels, units=units,
                               scaling=scaling, settings=settings, n_averages=cnt)


@_fill_doc
def welch(
    x: Signals | np.ndarray,
    fs: float | None = None,
    *,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple | np.ndarray = "hann",
    detrend: Literal["constant", "linear", False] = "constant",
    nfft: int | None = None,
    scaling: Literal["density", "spectrum"] = "density",
    workers: int | None = None,
    dtype: Literal["float64", "float32"] = "float64",
) -> Spectrum:
    """Power spectral density of every channel by Welch's averaged modified periodograms.

    Parameters
    ----------
    x : Signals or array_like, shape (n_channels, n_samples)
        The record (1-D: one channel).
    {welch_params}
    scaling : {'density', 'spectrum'}, optional
        unit²/Hz (default) or unit².
    workers : int, optional
        Threads splitting the segments; default None: the usable cores (see :func:`csd_matrix`).
    dtype : {'float64', 'float32'}, optional
        Precision of the segments and FFTs, float64 sums (see :func:`csd_matrix`); default float64.

    Returns
    -------
    Spectrum
        ``values`` shape (n_channels, nfft // 2 + 1), equal to ``scipy.signal.welch`` row by row;
        unit²/Hz (density) or unit² (spectrum).

    Raises
    ------
    TypeError
        If `x` is complex.
    ValueError
        As :func:`csd_matrix`; also when a channel has no segment free of NaN/Inf.

    Warns
    -----
    FewAveragesWarning
        As :func:`csd_matrix`.

    See Also
    --------
    csd_matrix : All channel pairs (cross-spectral densities) in the same pass.
    amplitude_spectrum : Amplitude (not power) per line.
    spectrogram : Short-time spectra over time.

    Notes
    -----
    ``P(f_k) = (2 / (K fs Σw²)) Σ_s |X_s(f_k)|²``. With ``scaling='spectrum'`` a sine of amplitude
    A, centred on a bin, peaks at ``A²/2`` for any window; with ``'density'`` the integral
    ``Σ P df`` is the mean square (Parseval). Segments touching a NaN/Inf sample are skipped per
    channel; ``Spectrum.n_averages`` gives each channel's count of segments used.

    References
    ----------
    .. [1] P. D. Welch, IEEE Trans. Audio Electroacoust. AU-15, 70–73, 1967.

    Examples
    --------
    >>> import numpy as np
    >>> fs, A = 1000.0, 2.0
    >>> t = np.arange(10_000) / fs
    >>> s = welch(A * np.sin(2 * np.pi * 100.0 * t), fs, nperseg=1000, scaling="spectrum")
    >>> round(float(s.values[0].max()), 6)   # A²/2
    2.0
    """
    acc, channels, units, settings, cnt = _welch_pass(x, fs, nperseg, noverlap, window, detrend, nfft, scaling,
                                                      workers, cross=False, dtype=dtype)
    return Spectrum(frequencies=acc.frequencies(), values=acc.result(scaling), channels=channels,
                    units=_power_units(units, scaling), scaling=scaling, settings=settings, n_averages=cnt)


def amplitude_spectrum(
    x: Signals | np.ndarray,
    fs: float | None = None,
    *,
    window: str | tuple = "hann",
    nperseg: int | None = None,
    noverlap: int | None = None,
    detrend: Literal["constant", "linear", False] = "constant",
) -> Spectrum:
    """Peak amplitude spectrum with window amplitude correction.

    Parameters
    ----------
    x : Signals or array_like, shape (n_channels, n_samples)
    fs : float, optional
        Hz.
    window : str or tuple, optional
        Default ``'hann'`` (periodic); ``'flattop'`` gives amplitudes accurate between bins.
    nperseg : int, optional
        Default: the whole record (one FFT). Otherwise the RMS average over Welch segments.
    noverlap : int, optional
        Default ``nperseg // 2``.
    detrend : {'constant', 'linear', False}, optional
        Per-segment detrending; default ``'constant'`` removes the mean, so a DC offset reads 0.
        With False the 0 Hz line reads the mean (as ``scipy.signal.periodogram(x, detrend=False)``).

    Returns
    -------
    Spectrum
        ``scaling='amplitude'``; a sine of amplitude A on a bin reads A (signal units).

    See Also
    --------
    welch : Power (``'density'`` or ``'spectrum'``) per line.

    Notes
    -----
    ``A(f_k) = 2 |X(f_k)| / Σw`` (DC and Nyquist not doubled), the amplitude ("coherent gain")
    correction; computed as ``sqrt(2 P)`` from the ``'spectrum'``-scaled Welch estimate P, which is
    that value for one segment and its RMS average for several (Brandt, *Noise and Vibration
    Analysis*, Wiley 2011, §9.3).

    References
    ----------
    .. [1] A. Brandt, *Noise and Vibration Analysis: Signal Analysis and Experimental Procedures*,
       Wiley, 2011.
    """
    data, fs, channels, units = unpack_signals(x, fs)
    n = data.shape[1]
    nperseg = n if nperseg is None else nperseg
    sp = welch(data, fs, nperseg=nperseg, noverlap=noverlap, window=window, detrend=detrend, scaling="spectrum")
    amp = np.sqrt(sp.values)  # RMS of each line; peak = sqrt(2) RMS except at DC and Nyquist
    last = None if sp.settings["nfft"] % 2 else -1
    amp[:, 1:last] *= np.sqrt(2.0)
    return Spectrum(frequencies=sp.frequencies, values=amp, channels=channels, units=units, scaling="amplitude",
                    settings=dict(sp.settings), n_averages=sp.n_averages)


def _resolve(G: CrossSpectralMatrix, chans: Sequence[Channel] | Channel) -> list[int]:
    if isinstance(chans, (str, int, np.integer)):
        chans = [chans]
    return [G.index(c) for c in chans]


def frf_kind(input_units: Sequence[str], output_units: Sequence[str]) -> tuple[str | None, str]:
    """FRF kind and unit string from channel units (``N`` in, ``m/s^2`` | ``m/s`` | ``m`` out).

    Parameters
    ----------
    input_units : sequence of str
        Units of the input channels.
    output_units : sequence of str
        Units of the output channels.

    Returns
    -------
    kind : {'accelerance', 'mobility', 'receptance'} or None
        When every input is in ``N`` and every output in one of ``m/s^2``, ``m/s``, ``m``;
        else None.
    units : str
        The kind's units; else ``"output/input"`` when each side has a single unit (``""``
        when both are empty), ``""`` for mixed units.
    """
    ins, outs = set(input_units), set(output_units)
    if ins == {"N"} and len(outs) == 1:
        kind = kind_of_response_unit(outs.pop())
        if kind:
            return kind, FRF_KIND_TABLE[kind].unit
    if len(ins) == 1 and len(outs) == 1:
        i, o = ins.pop(), outs.pop()
        return None, (f"{o}/{i}" if i or o else "")
    return None, ""


@_fill_doc
def frf(
    x: Signals | np.ndarray | CrossSpectralMatrix,
    inputs: Sequence[Channel] | Channel,
    outputs: Sequence[Channel] | Channel | None = None,
    *,
    estimator: Literal["H1", "H2", "Hv"] = "H1",
    fs: float | None = None,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple | np.ndarray = "hann",
    detrend: Literal["constant", "linear", False] = "constant",
    nfft: int | None = None,
    kind: str | None = None,
    workers: int | None = None,
    dtype: Literal["float64", "float32"] = "float64",
) -> FRF:
    """Frequency response function estimate between input and output channels.

    Parameters
    ----------
    x : Signals, array_like (n_channels, n_samples) or CrossSpectralMatrix
        The record, or its cross-spectral matrix computed once for several estimates.
    inputs : channel or sequence of channels
        Input (excitation, ``exc``) channel names or indices, e.g. a force in N.
    outputs : channel or sequence of channels, optional
        Response (``resp``) channels; default all channels that are not inputs.
    estimator : {'H1', 'H2', 'Hv'}, optional
        ``H1 = Gxy / Gxx`` (least squares, unbiased by output noise), ``H2 = Gyy / Gyx`` (unbiased
        by input noise; one input, or as many inputs as outputs) or ``Hv`` (total least squares,
        the smallest eigenvector of the ``[inputs, output]`` spectral matrix per output); with
        ``Gxy = E[conj(X) Y]`` as in Notes.
    {welch_params}
        The Welch settings are ignored when `x` is a CrossSpectralMatrix.
    kind : {'accelerance', 'mobility', 'receptance'}, optional
        Declare the FRF kind; default inferred from the channel units (N in; m/s², m/s or m out).
    workers : int, optional
        Threads of the spectral pass; default None: the usable cores (see :func:`csd_matrix`).
    dtype : {'float64', 'float32'}, optional
        Precision of the segments and FFTs, float64 sums (see :func:`csd_matrix`); default float64.
        (`workers` and `dtype` are ignored when `x` is a CrossSpectralMatrix.) From a record, the
        spectral matrix is computed in reference mode with the inputs as references (only the
        input rows/columns and the diagonal, ``C·R + C`` products), except H2 with several inputs.

    Returns
    -------
    FRF
        ``H[f, output, input]`` and the ordinary (one input) or multiple (several inputs)
        coherence ``[f, output]``.

    Raises
    ------
    ValueError
        If a channel is both input and output, H2 is asked with more inputs than outputs, or an
        option is unknown.
    KeyError
        If a channel name is not in the record.

    See Also
    --------
    csd_matrix : The spectral matrix the estimators read; pass it as `x` for several estimates.
    coherence : Ordinary coherence of channel pairs.
    multiple_coherence : Coherence of each output with all inputs together.
    frf_periodic : H1 from whole periods of a periodic excitation.
    vibroscope.modal.lscf : Poles from the FRF (LSCF/polyMAX); :func:`vibroscope.modal.lsfd` the shapes.
    vibroscope.modal.peak_picking : Modes from the FRF's peaks.

    Notes
    -----
    With ``Sxx[a, b] = E[conj(X_a) X_b]``, ``Sxy[a, o] = E[conj(X_a) Y_o]`` and ``Y = H X``:
    H1 solves ``Sxx Hᵀ = Sxy``. For one input, H1 = Gxy/Gxx, H2 = Gyy/Gyx and
    ``Hv = (Gyy − Gxx + sqrt((Gxx − Gyy)² + 4|Gxy|²)) / (2 Gyx)``, with ``|H1| ≤ |Hv| ≤ |H2|``
    (Bendat & Piersol 2010, §6.1.4, §9.1; Rocklin, Crowley & Vold 1985 for Hv).

    With missing samples (NaN/Inf) every entry ``G_ij`` of the spectral matrix is averaged over
    the segments valid for its pair and divided by its own count, and H1, H2, Hv and the coherence
    all use these entries: with unequal counts ``Gxx``, ``Gxy`` and ``Gyy`` come from different
    segment sets (so γ² may slightly exceed 1 before clipping). ``settings['n_averages']`` is the
    smallest count over the pairs used.

    References
    ----------
    .. [1] J. S. Bendat and A. G. Piersol, *Random Data*, 4th ed., Wiley, 2010.
    .. [2] G. T. Rocklin, J. Crowley and H. Vold, "A comparison of H1, H2, and Hv frequency response
       functions", Proc. 3rd IMAC, 1985.

    Examples
    --------
    A gain of 2.5 with output noise of unit variance: H1 recovers the gain; H2 is biased up by the
    noise, by ``1 / γ² = (6.25 + 1) / 6.25``:

    >>> import numpy as np
    >>> from vibroscope import Signals
    >>> rng = np.random.default_rng(0)
    >>> x = rng.standard_normal(100_000)
    >>> y = 2.5 * x + rng.standard_normal(100_000)
    >>> sig = Signals(data=np.vstack([x, y]), fs=1000.0, channels=["/f.x", "/a.x"], units=["N", "m/s^2"])
    >>> h1 = frf(sig, "/f.x", nperseg=1000)
    >>> h1.kind, h1.H.shape  # H[f, output, input]; N in, m/s² out: accelerance
    ('accelerance', (501, 1, 1))
    >>> round(float(np.abs(h1.H[1:-1, 0, 0]).mean()), 2), round(float(h1.coherence[1:-1, 0].mean()), 2)
    (2.5, 0.86)
    >>> h2 = frf(sig, "/f.x", estimator="H2", nperseg=1000)
    >>> round(float(np.abs(h2.H[1:-1, 0, 0]).mean()), 2)  # 2.5 · 7.25 / 6.25
    2.9
    """
    check_option("estimator", estimator, ("H1", "H2", "Hv"))
    if isinstance(x, CrossSpectralMatrix):
        G = x
    else:
        # H1, Hv and the coherence read only the input rows/columns and the diagonal: reference mode
        # (C·R + C products); H2 with several inputs needs the output block too
        refs = inputs if estimator != "H2" or isinstance(inputs, (str, int, np.integer)) or len(inputs) == 1 else None
        G = csd_matrix(x, fs, nperseg=nperseg, noverlap=noverlap, window=window, detrend=detrend, nfft=nfft,
                       workers=workers, dtype=dtype, references=refs)
    ii = _resolve(G, inputs)
    oo = [i for i in range(G.n_channels) if i not in ii] if outputs is None else _resolve(G, outputs)
    if set(ii) & set(oo):
        raise ValueError(f"channels {[G.channels[i] for i in set(ii) & set(oo)]} are both input and output")
    if not oo:
        raise ValueError("no output channel")
    Sxx = G.G[:, ii][:, :, ii]  # (f, a, b)
    Sxy = G.G[:, ii][:, :, oo]  # (f, a, o)
    Syy = np.real(np.einsum("foo->fo", G.G[:, oo][:, :, oo]))  # (f, o)
    nf, ni, no = Sxx.shape[0], len(ii), len(oo)
    with np.errstate(divide="ignore", invalid="ignore"):
        if estimator == "H1":
            H = _batched_solve(Sxx, Sxy).transpose(0, 2, 1)
        elif estimator == "H2":
            if ni == 1:
                H = (Syy / np.conj(Sxy[:, 0, :]))[:, :, None]
            elif ni == no:
                Syx = G.G[:, oo][:, :, ii]
                Syy_full = G.G[:, oo][:, :, oo]
                H = _batched_solve(Syx, Syy_full).transpose(0, 2, 1)
            else:
                raise ValueError(f"H2 needs one input or as many inputs as outputs, got {ni=} and {no=}")
        else:  # Hv: total least squares per output
            H = np.empty((nf, no, ni), complex)
            for k, o in enumerate(oo):
                idx = ii + [o]
                Ga = G.G[:, idx][:, :, idx]
                Ga = 0.5 * (Ga + np.conj(Ga.transpose(0, 2, 1)))
                _, V = np.linalg.eigh(Ga)
                v = V[:, :, 0]  # smallest eigenvalue's eigenvector
                H[:, k, :] = -(v[:, :ni] / v[:, ni : ni + 1])
        coh = _multiple_coherence(Sxx, Sxy, Syy)
    settings = dict(G.settings)
    if G.n_averages is not None:
        settings["n_averages"] = int(G.n_averages[np.ix_(ii + oo, ii + oo)].min())
    in_units = [G.units[i] for i in ii]
    out_units = [G.units[o] for o in oo]
    k_inf, unit = frf_kind(in_units, out_units)
    if kind is not None:
        check_option("kind", kind, FRF_KINDS)
        k_inf, unit = kind, FRF_KIND_TABLE[kind].unit
    return FRF(frequencies=G.frequencies, H=H, coherence=coh, inputs=[G.channels[i] for i in ii],
               outputs=[G.channels[o] for o in oo], estimator=estimator, kind=k_inf, units=unit, settings=settings)


def _batched_solve(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Solve ``A[f] X[f] = B[f]``; singular frequencies (e.g. no excitation) give NaN."""
    out = np.full(np.broadcast_shapes(A.shape[:-1] + (B.shape[-1],), B.shape), np.nan + 0j)
    if A.shape[-1] == 1:
        return B / A
    try:
        return np.linalg.solve(A, B)
    except np.linalg.LinAlgError:
        for f in range(A.shape[0]):
            try:
                out[f] = np.linalg.solve(A[f], B[f])
            except np.linalg.LinAlgError:
                pass
        return out


def _multiple_coherence(Sxx: np.ndarray, Sxy: np.ndarray, Syy: np.ndarray) -> np.ndarray:
    """γ²_{y:x} = Sxyᴴ Sxx⁻¹ Sxy / Syy per output, shape (f, o)."""
    sol = _batched_solve(Sxx, Sxy)  # (f, a, o)
    num = np.real(np.einsum("fao,fao->fo", np.conj(Sxy), sol))
    coh = num / Syy
    return np.clip(coh, 0.0, 1.0, out=coh, where=np.isfinite(coh))


@_fill_doc
def coherence(
    x: Signals | np.ndarray | CrossSpectralMatrix,
    fs: float | None = None,
    *,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple | np.ndarray = "hann",
    detrend: Literal["constant", "linear", False] = "constant",
    nfft: int | None = None,
) -> Coherence:
    """Ordinary coherence of every channel pair.

    Parameters
    ----------
    x : Signals, array_like (n_channels, n_samples) or CrossSpectralMatrix
        The record, or its cross-spectral matrix.
    {welch_params}

    Returns
    -------
    Coherence
        Unpacks as ``(frequencies, gamma2)``: ``frequencies`` in Hz, shape (n_freqs,), and
        ``gamma2`` of shape (n_freqs, n_channels, n_channels),
        ``γ²_ij = |G_ij|² / (G_ii G_jj)`` ∈ [0, 1]; ``gamma2[:, i, j]`` equals
        ``scipy.signal.coherence(x[i], x[j])``.

    See Also
    --------
    multiple_coherence : An output against several inputs together.
    frf : The FRF with its coherence.

    References
    ----------
    .. [1] J. S. Bendat and A. G. Piersol, *Random Data*, 4th ed., Wiley, 2010, §5.2.5.
    """
    G = x if isinstance(x, CrossSpectralMatrix) else csd_matrix(
        x, fs, nperseg=nperseg, noverlap=noverlap, window=window, detrend=detrend, nfft=nfft)
    d = np.real(np.einsum("fii->fi", G.G))
    with np.errstate(divide="ignore", invalid="ignore"):
        g2 = np.abs(G.G) ** 2 / (d[:, :, None] * d[:, None, :])
    return Coherence(G.frequencies, g2, G.channels, dict(G.settings))


def multiple_coherence(
    x: Signals | np.ndarray | CrossSpectralMatrix,
    inputs: Sequence[Channel] | Channel,
    outputs: Sequence[Channel] | Channel | None = None,
    **welch_kw: Any,
) -> MultipleCoherence:
    """Multiple coherence of each output with all `inputs` together.

    Parameters
    ----------
    x : Signals, array_like (n_channels, n_samples) or CrossSpectralMatrix
        The record or its cross-spectral matrix.
    inputs : channel or sequence of channels
        Input channels (names or indices).
    outputs : channel or sequence of channels, optional
        Output channels; default every other channel.
    **welch_kw
        Welch settings passed to :func:`frf` (``fs``, ``nperseg``, ...).

    Returns
    -------
    MultipleCoherence
        Unpacks as ``(frequencies, gamma2)``: ``frequencies`` in Hz, shape (n_freqs,), and
        ``gamma2`` of shape (n_freqs, n_outputs),
        ``γ²_{y:x} = Gxyᴴ Gxx⁻¹ Gxy / Gyy`` ∈ [0, 1]; equals the ordinary coherence for one input.

    See Also
    --------
    coherence : Ordinary coherence of channel pairs.
    frf : The FRF with this coherence.

    References
    ----------
    .. [1] J. S. Bendat and A. G. Piersol, *Random Data*, 4th ed., Wiley, 2010, §7.3.
    """
    h = frf(x, inputs, outputs, **welch_kw)
    return MultipleCoherence(h.frequencies, h.coherence, h.inputs, h.outputs, dict(h.settings))


def spectrogram(
    x: Signals | np.ndarray,
    fs: float | None = None,
    *,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple = "hann",
    detrend: Literal["constant", "linear", False] = "constant",
    scaling: Literal["density", "spectrum"] = "density",
) -> Spectrogram:
    """Short-time spectra of every channel (``scipy.signal.spectrogram``, one-sided).

    Parameters
    ----------
    x : Signals or array_like, shape (n_channels, n_samples)
        The record.
    fs : float, optional
        Sampling frequency in Hz (from `x` when it is Signals).
    nperseg : int, optional
        Segment length; default ``min(256, n_samples)``.
    noverlap : int, optional
        Overlap; default ``nperseg // 2`` (scipy's spectrogram: ``nperseg // 8``), as :func:`welch`.
    window : str or tuple, optional
        Default ``'hann'`` (scipy's spectrogram: Tukey 0.25).
    detrend : {'constant', 'linear', False}, optional
        Per-segment detrending.
    scaling : {'density', 'spectrum'}, optional
        unit²/Hz or unit².

    Returns
    -------
    Spectrogram
        ``values`` shape (n_channels, n_freqs, n_times).

    See Also
    --------
    welch : The spectra averaged over the whole record.
    """
    data, fs, channels, units = unpack_signals(x, fs)
    st = segment_settings(data.shape[1], nperseg=nperseg, noverlap=noverlap, window=window,
                          detrend=detrend)
    f, t, S = scipy.signal.spectrogram(data, fs, window=st.window, nperseg=st.nperseg,
                                       noverlap=st.noverlap, detrend=detrend, scaling=scaling, axis=-1)
    u = _power_units(units, scaling)
    return Spectrogram(frequencies=f, times=t, values=S, channels=channels, units=u, scaling=scaling,
                       settings=settings_dict(fs, st, S.shape[-1]))
