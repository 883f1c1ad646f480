"""Resampling helpers of the time simulation: band-limited upsampling of sampled inputs
and MATLAB-style multistage FIR decimation of simulated outputs.

Conventions: sample ``k`` of a record lands on sample ``k * factor`` of its upsampled
version and output ``j`` of a decimation belongs to input ``j * factor`` (no delay).

Resampling in vibroscope: three designs, each for its own job
-------------------------------------------------------------
* here, **integer factors around a simulation**: :func:`upsample` (band-limited),
  :func:`decimate_fir` (linear-phase FIR in prime stages, MATLAB ``decimate(x, r, 'fir')``)
  and :func:`decimate_sharp` (one Kaiser-window FIR, flat to 0.46 of the output rate: the
  digital anti-aliasing filter of a sigma-delta converter or a decimating recorder).
  Sample alignment is exact (no delay) and the FIR design is fixed, because the simulated
  outputs must reproduce references made that way (the Bouc-Wen benchmark [1]_) and
  because :func:`~vibroscope.models.simulate.simulate` and its tests rely on output ``k``
  belonging to input ``k``;
* :func:`vibroscope.io.timebase.resample_to_grid`, **irregular time stamps onto a uniform
  grid** at any (non-integer) rate ratio: a shape-preserving cubic (PCHIP) through the
  samples, never outside two neighbours, with a Butterworth anti-alias low-pass when the source
  is faster. Integer-factor filters do not
  apply to jittered, gapped stamps;
* :func:`vibroscope.pipeline.decimate`, **reducing a uniform record to the analysis band**
  before spectral estimation: an order-9 Chebyshev I low-pass (zero phase, unit gain at
  0 Hz) in stages of at most 10 for any integer factor, including large primes for which a
  30th-order FIR per stage would alias; only the band below 0.4 fs is used afterwards.

The three are kept apart on purpose: merging them would change simulated records (FIR vs
IIR), analysed spectra, or the treatment of irregular logs.

References
----------
.. [1] J. P. Noël, M. Schoukens, "Hysteretic benchmark with a dynamic nonlinearity",
   Workshop on Nonlinear System Identification Benchmarks, Brussels, 2016.
"""

from __future__ import annotations

import functools

from typing import Literal

import numpy as np
from scipy import signal

__all__ = ["upsample", "decimate_fir", "decimate_sharp"]


def _prime_factors(n: int) -> list[int]:
    out, p = [], 2
    while n > 1:
        while n % p == 0:
            out.append(p)
            n //= p
        p += 1
    return out


def upsample(
    u: np.ndarray, factor: int, *, method: Literal["fft", "poly", "linear"] = "poly", periodic: bool = False
) -> np.ndarray:
    """Band-limited (or linear) upsampling along the last axis by an integer `factor`.

    Sample ``k`` of the input lands on sample ``k * factor`` of the output (no delay).

    Parameters
    ----------
    u : ndarray, shape (..., n)
    factor : int
        Upsampling factor, >= 1.
    method : {"fft", "poly", "linear"}
        ``"fft"``: ideal band-limited interpolation of a periodic record (zero-padding the
        spectrum; the Nyquist bin is split). ``"poly"``: polyphase FIR interpolation
        (:func:`scipy.signal.resample_poly`, Kaiser window beta 10, 40 taps per phase
        either side), zero outside the record. ``"linear"``: linear interpolation.
    periodic : bool
        Treat the record as one period (``"fft"`` is exact then; ``"poly"`` and
        ``"linear"`` wrap around).

    Returns
    -------
    ndarray, shape (..., n * factor)

    Raises
    ------
    ValueError
        If `factor` < 1 or `method` is unknown.
    """
    factor = int(factor)
    if factor < 1:
        raise ValueError(f"{factor=} must be >= 1")
    u = np.asarray(u, dtype=float)
    if factor == 1:
        return u.copy()
    n = u.shape[-1]
    if method == "fft":
        U = np.fft.rfft(u, axis=-1)
        if n % 2 == 0:
            U[..., -1] *= 0.5
        N = n * factor
        Z = np.zeros(u.shape[:-1] + (N // 2 + 1,), dtype=complex)
        Z[..., : U.shape[-1]] = U
        return np.fft.irfft(Z, N, axis=-1) * factor
    if method == "poly":
        half = 40 * factor
        h = _kaiser_lowpass(factor) * factor
        if periodic:
            ext = np.concatenate([u[..., -(half // factor + 2):], u, u[..., : half // factor + 2]], axis=-1)
            pre = (half // factor + 2) * factor
        else:
            ext, pre = u, 0
        up = np.zeros(ext.shape[:-1] + (ext.shape[-1] * factor,))
        up[..., ::factor] = ext
        y = signal.oaconvolve(up, h.reshape((1,) * (u.ndim - 1) + (-1,)), mode="full", axes=-1)
        return y[..., half + pre : half + pre + n * factor]
    if method == "linear":
        t = np.arange(n * factor) / factor
        flat = u.reshape(-1, n)
        if periodic:
            out = [np.interp(t, np.arange(n + 1), np.append(r, r[0])) for r in flat]
        else:
            out = [np.interp(t, np.arange(n), r) for r in flat]
        return np.asarray(out).reshape(u.shape[:-1] + (n * factor,))
    raise ValueError(f"{method=} must be 'fft', 'poly' or 'linear'")


@functools.lru_cache(maxsize=64)
def _fir1(order: int, r: int) -> np.ndarray:
    """``fir1(order, 1/r)`` (:func:`scipy.signal.firwin`), designed once per (order, r): the
    gap diagnosis decimates every simulation, thousands per run. Read-only."""
    b = signal.firwin(order + 1, 1.0 / r)
    b.flags.writeable = False
    return b


def decimate_fir(x: np.ndarray, factor: int, *, order: int = 30, periodic: bool = False) -> np.ndarray:
    """Low-pass and downsample by `factor` in prime stages, like MATLAB ``decimate(x, r, 'fir')``.

    Each stage ``r`` filters with the order-`order` Hamming-window FIR ``fir1(order, 1/r)``
    (:func:`scipy.signal.firwin`), compensates its group delay (zero phase), extends the
    ends by point reflection (``2 x[0] - x[i]``) against edge transients, and keeps every
    ``r``-th sample starting with the first: output ``j`` belongs to input ``j * r``. The
    Bouc-Wen benchmark's reference outputs were made this way with stages 2, 2, 5 [1]_.

    Parameters
    ----------
    x : ndarray, shape (..., n)
    factor : int
        Total decimation factor (split into its prime factors, smallest first).
    order : int
        FIR order per stage (even).
    periodic : bool
        Filter circularly (the record is one period of a periodic signal).

    Returns
    -------
    ndarray, shape (..., ceil(n / factor)) (periodic: ``n / factor``, `n` must divide)

    References
    ----------
    .. [1] J. P. Noël, M. Schoukens, "Hysteretic benchmark with a dynamic nonlinearity", 2016.
    """
    x = np.asarray(x, dtype=float)
    if int(factor) < 1:
        raise ValueError(f"{factor=} must be >= 1")
    for r in _prime_factors(int(factor)):
        b = _fir1(int(order), int(r))
        half = order // 2
        n = x.shape[-1]
        if periodic:
            if n % r:
                raise ValueError(f"periodic decimation needs a length {n=} divisible by {r}")
            ext = np.concatenate([x[..., -half:], x, x[..., :half]], axis=-1)
        else:
            m = order + 1
            pre = 2 * x[..., :1] - x[..., m:0:-1]
            post = 2 * x[..., -1:] - x[..., -2 : -m - 2 : -1]
            ext = np.concatenate([pre[..., -half:], x, post[..., :half]], axis=-1)
        # every r-th sample of the 'valid' convolution, computed polyphase (upfirdn) rather
        # than filtering at the full rate: valid[j] = full[j + order]; shifting ext by
        # order % r makes the kept full indices multiples of r
        n_out = (ext.shape[-1] - order + r - 1) // r
        off = order % r
        y = signal.upfirdn(b, ext[..., off:], 1, r, axis=-1)
        k0 = (order - off) // r
        x = y[..., k0 : k0 + n_out]
    return x


@functools.lru_cache(maxsize=64)
def _kaiser_lowpass(r: int) -> np.ndarray:
    """The Kaiser-window (beta 10) low-pass of :func:`upsample`'s ``"poly"`` reconstruction,
    ``80 r + 1`` taps, cut at ``1 / r`` of the fine Nyquist; unit DC gain. Read-only."""
    half = 40 * r
    b = signal.firwin(2 * half + 1, 1.0 / r, window=("kaiser", 10.0))
    b.flags.writeable = False
    return b


def decimate_sharp(x: np.ndarray, factor: int, *, periodic: bool = False) -> np.ndarray:
    """Low-pass and downsample by `factor` with one sharp linear-phase FIR: flat in band, so
    that a simulation's outputs meet a record made by a sharp anti-aliasing filter.

    The filter is the Kaiser-window (beta 10) windowed sinc of :func:`upsample`'s ``"poly"``
    reconstruction, ``80 factor + 1`` taps cut at the output Nyquist ``fs_out / 2`` [1]_: its
    pass band is flat (within 1e-4) to about 0.46 ``fs_out`` and its stop band (below -90 dB)
    begins at about 0.54 ``fs_out``, so a nonlinearity's harmonics above ``fs_out / 2`` are
    removed while the band the input reconstruction carries passes unchanged. That is what a
    sigma-delta converter's digital decimation filter, or a recorder that decimates a fast
    record with a sharp low-pass, does; :func:`decimate_fir` (MATLAB's order-30 stages) rolls
    off from about 0.3 ``fs_out`` instead. Zero phase (the group delay removed), the ends
    extended by point reflection (``2 x[0] - x[i]``) against edge transients; output ``j``
    belongs to input ``j * factor``.

    Parameters
    ----------
    x : ndarray, shape (..., n)
    factor : int
        Decimation factor, >= 1.
    periodic : bool
        Filter circularly (the record is one period; `n` must be a multiple of `factor`).

    Returns
    -------
    ndarray, shape (..., ceil(n / factor)) (periodic: ``n / factor``)

    Raises
    ------
    ValueError
        If `factor` < 1, or a periodic `n` is not a multiple of `factor`.

    References
    ----------
    .. [1] A. V. Oppenheim, R. W. Schafer, *Discrete-Time Signal Processing*, 3rd ed., 2010,
       sec. 7.6 (the Kaiser window method) and sec. 4.6 (decimation).
    """
    x = np.asarray(x, dtype=float)
    r = int(factor)
    if r < 1:
        raise ValueError(f"{factor=} must be >= 1")
    if r == 1:
        return x.copy()
    b = _kaiser_lowpass(r)
    half = (len(b) - 1) // 2
    n = x.shape[-1]
    if periodic:
        if n % r:
            raise ValueError(f"periodic decimation needs a length {n=} divisible by {r}")
        ext = np.take(x, np.arange(-half, n + half) % n, axis=-1)  # circular extension
    else:
        m = min(half, n - 1)
        pre = 2 * x[..., :1] - x[..., m:0:-1]
        post = 2 * x[..., -1:] - x[..., -2 : -m - 2 : -1]
        pad = [np.zeros(x.shape[:-1] + (half - m,))] if half > m else []
        ext = np.concatenate(pad + [pre, x, post] + pad, axis=-1)
    # the 'valid' convolution's sample j is centred on x[j]; keep j = 0, r, 2r, ... (the
    # overlap-add FFT convolution is about twice as fast as the polyphase one for these lengths)
    n_out = n // r if periodic else (n + r - 1) // r
    y = signal.oaconvolve(ext, b.reshape((1,) * (x.ndim - 1) + (-1,)), mode="valid", axes=-1)
    return y[..., ::r][..., :n_out]
