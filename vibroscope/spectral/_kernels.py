"""Compiled (numba) kernels of the cross-spectral engine; loaded on the engine's first pass.

Two kernels, both ``nogil`` so that the engine's worker threads run them on all cores:

* :func:`prepare_segments`: one pass per segment that detrends (constant or linear), applies
  the window and checks finiteness, writing the FFT input block (the three numpy passes mean,
  subtract, multiply fused into one);
* :func:`accumulate_pairs`: ``S[p, f] += Σ_s conj(X_i,s[f]) X_j,s[f]`` for a list of channel
  pairs ``(i, j)`` (the upper triangle, the diagonal, or the columns of reference channels),
  tiled over frequency so that the accumulator tile and the block's spectra stay in cache, and
  two pairs of one first channel at a time (its values loaded once for both: measured 1.1–1.25×
  over one pair at a time from 2 to 64 channels; three or more at a time spill registers and are
  slower); float64 accumulation whatever the precision of ``X``.

Kept apart from :mod:`vibroscope.spectral._engine` so that ``import vibroscope.spectral`` does not
import numba (start-up, issue #9).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["prepare_segments", "accumulate_pairs", "frequency_tile"]

# reassociation lets the reductions and products vectorize; no nnan/ninf: finiteness is tested
_JIT = dict(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract", "nsz", "arcp"})

#: bytes of the accumulator tile of :func:`accumulate_pairs` (16 B × pairs × tile); measured: a
#: 128-bin tile is the fastest from 4 to 64 channels (2080 pairs, 4.3 MB), smaller tiles lose more
#: to the per-tile de-interleave than they gain in cache
_TILE_BYTES = 4400 * 1024


def frequency_tile(n_pairs: int) -> int:
    """Frequency bins per tile of :func:`accumulate_pairs`.

    Parameters
    ----------
    n_pairs : int
        Number of channel pairs accumulated.

    Returns
    -------
    int
        32 to 128, a multiple of 8, with the accumulator tile (16 B × `n_pairs` × tile) within
        :data:`_TILE_BYTES` where possible (128 up to 64 channels).
    """
    return int(max(32, min(128, _TILE_BYTES // (16 * max(1, n_pairs)) // 8 * 8)))


@numba.njit(**_JIT)
def prepare_segments(flat, row_stride, s0, step, win, mode, out, ok):  # pragma: no cover - compiled
    """Detrend, window and check each segment of a block.

    Parameters
    ----------
    flat : ndarray, shape (m,), float64 or float32, contiguous
        The record's memory: sample ``k`` of channel ``c`` is ``flat[c * row_stride + k]`` (a
        C-contiguous 1-D view, so that the loops vectorise; see ``_engine._flat_rows``).
    row_stride : int
        Elements between the starts of two channels' rows.
    s0 : int
        Index of the block's first segment (it starts at sample ``s0 * step``).
    step : int
        Hop between segment starts in samples.
    win : ndarray, shape (nperseg,), float64
        Window.
    mode : int
        0: no detrend, 1: constant (mean), 2: linear (least-squares line).
    out : ndarray, shape (n_channels, n_block, nperseg) or longer last axis, float32 or float64
        FFT input, written ``w · detrend(x)``; a segment holding NaN/±Inf is written as zeros.
    ok : ndarray, shape (n_channels, n_block), bool
        Written: whether the segment is finite.
    """
    n_ch, nb = ok.shape
    n = win.shape[0]
    tc0 = 0.5 * (n - 1)
    stt = n * (n * n - 1.0) / 12.0  # Σ (t - tc0)²
    for c in range(n_ch):
        for b in range(nb):
            a = c * row_stride + (s0 + b) * step
            row = flat[a : a + n]
            o = out[c, b]
            s = 0.0
            st = 0.0
            if mode == 2:
                for k in range(n):
                    s += row[k]
                    st += (k - tc0) * row[k]
            else:
                for k in range(n):
                    s += row[k]
            m = s / n
            if not np.isfinite(s) or not np.isfinite(st):  # NaN, or ±Inf (alone or as Inf - Inf)
                ok[c, b] = False
                for k in range(n):
                    o[k] = 0.0
                continue
            ok[c, b] = True
            if mode == 0:
                for k in range(n):
                    o[k] = row[k] * win[k]
            elif mode == 1:
                for k in range(n):
                    o[k] = (row[k] - m) * win[k]
            else:
                slope = st / stt if n > 1 else 0.0
                for k in range(n):
                    o[k] = (row[k] - m - slope * (k - tc0)) * win[k]


@numba.njit(**_JIT)
def accumulate_pairs(X, ii, jj, acc, ftile):  # pragma: no cover - compiled
    """Add ``Σ_s conj(X[i, s]) · X[j, s]`` to ``acc[p]`` for every pair ``p = (ii[p], jj[p])``.

    Parameters
    ----------
    X : ndarray, shape (n_channels, n_block, 2 n_freqs), float32 or float64
        The block's spectra as interleaved (real, imaginary) pairs (a complex array's float view).
    ii, jj : ndarray of int64, shape (n_pairs,)
        The pairs' first (conjugated) and second channel.
    acc : ndarray, shape (n_pairs, 2 n_freqs), float64
        Accumulator of the products, interleaved (real, imaginary); updated in place.
    ftile : int
        Frequency bins per tile (:func:`frequency_tile`).
    """
    n_ch, nb, nf2 = X.shape
    nf = nf2 // 2
    npair = ii.shape[0]
    re = np.empty((4, n_ch, ftile))
    im = np.empty((4, n_ch, ftile))
    ar = np.empty((npair, ftile))
    ai = np.empty((npair, ftile))
    for f0 in range(0, nf, ftile):
        nt = min(ftile, nf - f0)
        ar[:, :] = 0.0
        ai[:, :] = 0.0
        for b0 in range(0, nb, 4):
            nu = min(4, nb - b0)
            for u in range(4):  # de-interleave the tile of 4 segments, in float64 (zeros past the block)
                for c in range(n_ch):
                    if u < nu:
                        for k in range(nt):
                            re[u, c, k] = X[c, b0 + u, 2 * (f0 + k)]
                            im[u, c, k] = X[c, b0 + u, 2 * (f0 + k) + 1]
                    else:
                        for k in range(nt):
                            re[u, c, k] = 0.0
                            im[u, c, k] = 0.0
            p = 0
            while p < npair:
                i = ii[p]
                j = jj[p]
                if p + 1 < npair and ii[p + 1] == i:  # two pairs of one channel i: its values loaded once
                    j2 = jj[p + 1]
                    for k in range(nt):
                        r0 = re[0, i, k]
                        m0 = im[0, i, k]
                        r1 = re[1, i, k]
                        m1 = im[1, i, k]
                        r2 = re[2, i, k]
                        m2 = im[2, i, k]
                        r3 = re[3, i, k]
                        m3 = im[3, i, k]
                        ar[p, k] += (r0 * re[0, j, k] + m0 * im[0, j, k] + r1 * re[1, j, k] + m1 * im[1, j, k]
                                     + r2 * re[2, j, k] + m2 * im[2, j, k] + r3 * re[3, j, k] + m3 * im[3, j, k])
                        ai[p, k] += (r0 * im[0, j, k] - m0 * re[0, j, k] + r1 * im[1, j, k] - m1 * re[1, j, k]
                                     + r2 * im[2, j, k] - m2 * re[2, j, k] + r3 * im[3, j, k] - m3 * re[3, j, k])
                        ar[p + 1, k] += (r0 * re[0, j2, k] + m0 * im[0, j2, k] + r1 * re[1, j2, k]
                                         + m1 * im[1, j2, k] + r2 * re[2, j2, k] + m2 * im[2, j2, k]
                                         + r3 * re[3, j2, k] + m3 * im[3, j2, k])
                        ai[p + 1, k] += (r0 * im[0, j2, k] - m0 * re[0, j2, k] + r1 * im[1, j2, k]
                                         - m1 * re[1, j2, k] + r2 * im[2, j2, k] - m2 * re[2, j2, k]
                                         + r3 * im[3, j2, k] - m3 * re[3, j2, k])
                    p += 2
                else:
                    for k in range(nt):
                        ar[p, k] += (re[0, i, k] * re[0, j, k] + im[0, i, k] * im[0, j, k]
                                     + re[1, i, k] * re[1, j, k] + im[1, i, k] * im[1, j, k]
                                     + re[2, i, k] * re[2, j, k] + im[2, i, k] * im[2, j, k]
                                     + re[3, i, k] * re[3, j, k] + im[3, i, k] * im[3, j, k])
                        ai[p, k] += (re[0, i, k] * im[0, j, k] - im[0, i, k] * re[0, j, k]
                                     + re[1, i, k] * im[1, j, k] - im[1, i, k] * re[1, j, k]
                                     + re[2, i, k] * im[2, j, k] - im[2, i, k] * re[2, j, k]
                                     + re[3, i, k] * im[3, j, k] - im[3, i, k] * re[3, j, k])
                    p += 1
        for p in range(npair):
            for k in range(nt):
                acc[p, 2 * (f0 + k)] += ar[p, k]
                acc[p, 2 * (f0 + k) + 1] += ai[p, k]
