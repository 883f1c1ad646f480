"""The cross-spectral engine's speed options (issue #9, targets 2 and 8): threads, float32 segments
with float64 sums, reference-channel mode, pieces fed in place, memory independent of length."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import scipy.signal as ss

from vibroscope import Signals
from vibroscope.spectral import CrossSpectralAccumulator, csd_matrix, frf, segment_settings, welch

RNG = np.random.default_rng(9)
FS = 1000.0
X = RNG.standard_normal((5, 40_000))
X[1] += 0.5 * X[0]  # correlated pairs: non-trivial cross-spectra
X[3] = 3.0 + np.convolve(X[2], [1.0, -0.6, 0.2], mode="same")  # an offset and a filtered copy
KW = dict(nperseg=512)


def _pairwise(x, **kw):
    n = x.shape[0]
    f, p = ss.csd(x[0], x[0], FS, **kw)
    out = np.empty((f.size, n, n), complex)
    for i in range(n):
        for j in range(n):
            out[:, i, j] = ss.csd(x[i], x[j], FS, **kw)[1]
    return out


REF = _pairwise(X, **KW)


@pytest.mark.parametrize("workers", [None, 1, 2, 3])
def test_threads_give_scipys_matrix(workers):
    G = csd_matrix(X, FS, workers=workers, **KW).G
    np.testing.assert_allclose(G, REF, rtol=0, atol=1e-13 * np.abs(REF).max())
    np.testing.assert_array_equal(csd_matrix(X, FS, workers=workers, **KW).G, G)  # deterministic


def test_default_threads_are_the_usable_cores_bounded_by_the_segments():
    from vibroscope.spectral.estimators import _n_workers

    assert _n_workers(4, 1000) == 4
    assert _n_workers(4, 40) == 1  # fewer than 32 segments per thread: one thread
    assert _n_workers(None, 10**6) >= 1
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="workers="):
            csd_matrix(X, FS, workers=bad, **KW)


@pytest.mark.parametrize("detrend", ["constant", "linear", False])
def test_float32_is_close_to_float64(detrend):
    """float32 segments and FFT, float64 sums: relative error ~1e-6 of the largest entry (the
    documented accuracy), and really single precision (not 1e-15)."""
    g64 = csd_matrix(X, FS, detrend=detrend, **KW)
    g32 = csd_matrix(X, FS, detrend=detrend, dtype="float32", **KW)
    err = np.abs(g32.G - g64.G).max() / np.abs(g64.G).max()
    assert 1e-9 < err < 5e-6
    assert g32.G.dtype == np.complex128 and g32.settings["dtype"] == "float32"
    p32 = welch(X.astype(np.float32), FS, dtype="float32", detrend=detrend, **KW).values
    p64 = welch(X, FS, detrend=detrend, **KW).values
    assert 1e-9 < np.abs(p32 - p64).max() / p64.max() < 5e-6


def test_float32_record_is_read_without_a_float64_copy():
    x = RNG.standard_normal((2, 2_000_000)).astype(np.float32)  # 16 MB; a float64 copy is 32 MB
    csd_matrix(x[:, :5000], FS, dtype="float32", nperseg=1024)  # kernels compiled outside the trace
    tracemalloc.start()
    g = csd_matrix(x, FS, dtype="float32", nperseg=1024)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 12e6
    p = ss.welch(x[1].astype(float), FS, nperseg=1024)[1]
    np.testing.assert_allclose(g.G[:, 1, 1].real, p, rtol=1e-4)


def test_reference_mode_equals_the_full_matrix_columns():
    refs = [0, 3]
    G = csd_matrix(X, FS, references=refs, **KW)
    assert G.settings["references"] == ("0", "3")
    for i in range(5):
        for j in range(5):
            if i == j or i in refs or j in refs:
                np.testing.assert_allclose(G.G[:, i, j], REF[:, i, j], rtol=0, atol=1e-13 * np.abs(REF).max())
            else:
                assert np.isnan(G.G[:, i, j]).all()
    again = csd_matrix(X, FS, references=[3, 0, 3], **KW)  # repeats ignored
    np.testing.assert_array_equal(again.G, G.G)
    by_name = csd_matrix(Signals(data=X, fs=FS, channels=list("abcde")), references="d", **KW)
    np.testing.assert_allclose(by_name.G[:, :, 3], REF[:, :, 3], rtol=0, atol=1e-13 * np.abs(REF).max())
    with pytest.raises(KeyError):
        csd_matrix(Signals(data=X, fs=FS, channels=list("abcde")), references="z", **KW)


def test_frf_through_reference_mode_equals_frf_of_the_full_matrix():
    full = csd_matrix(X, FS, **KW)
    for est in ("H1", "H2", "Hv"):
        a = frf(X, [0], [1, 2, 3], fs=FS, estimator=est, **KW)
        b = frf(full, [0], [1, 2, 3], estimator=est)
        np.testing.assert_allclose(a.H, b.H, rtol=1e-10)
        np.testing.assert_allclose(a.coherence, b.coherence, rtol=1e-10, atol=1e-14)
    a = frf(X, [0, 2], [1, 3, 4], fs=FS, **KW)  # multiple-input H1 and multiple coherence
    b = frf(full, [0, 2], [1, 3, 4])
    np.testing.assert_allclose(a.H, b.H, rtol=1e-9)
    np.testing.assert_allclose(a.coherence, b.coherence, rtol=1e-9, atol=1e-13)


def test_reference_accumulator_checks_and_merge():
    st = segment_settings(None, nperseg=256, noverlap=None, window="hann", detrend="constant")
    with pytest.raises(ValueError, match="references="):
        CrossSpectralAccumulator(3, FS, st, references=[3])
    with pytest.raises(ValueError, match="references="):
        CrossSpectralAccumulator(3, FS, st, cross=False, references=[0])
    a = CrossSpectralAccumulator(5, FS, st, references=[1])
    b = CrossSpectralAccumulator(5, FS, st)
    with pytest.raises(ValueError, match="references"):
        a.merge(b)
    with pytest.raises(ValueError, match="dtype"):
        b.merge(CrossSpectralAccumulator(5, FS, st, dtype="float32"))
    with pytest.raises(ValueError, match="'dtype' parameter"):
        CrossSpectralAccumulator(5, FS, st, dtype="float16")


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_pieces_of_any_length_equal_one_pass(dtype):
    """Pieces shorter than a segment, longer than many, and float32 pieces: the segments that
    straddle two pieces are found exactly (the piece is read in place, only the tail is joined)."""
    st = segment_settings(None, nperseg=300, noverlap=120, window="hann", detrend="linear")
    whole = CrossSpectralAccumulator(5, FS, st, dtype=dtype).update(X)
    acc = CrossSpectralAccumulator(5, FS, st, dtype=dtype)
    cuts = np.cumsum([1, 299, 7, 1000, 180, 181, 5000, 3])
    for piece in np.split(X, cuts, axis=1):
        acc.update(piece.astype(np.float32) if dtype == "float32" else piece)
    assert acc.n_segments == whole.n_segments == (X.shape[1] - 300) // 180 + 1
    np.testing.assert_allclose(acc.result(), whole.result(), rtol=0,
                               atol=(1e-6 if dtype == "float32" else 1e-13) * np.abs(whole.result()).max())


def test_nan_segments_are_skipped_per_pair_on_every_path():
    x = X.copy()
    x[2, 10_000] = np.nan
    x[4, 30_000:30_010] = np.inf
    for kw in (dict(), dict(dtype="float32"), dict(references=[2]), dict(workers=3)):
        G = csd_matrix(x, FS, **KW, **kw)
        step = 256
        seg_ok = lambda ch: np.array([np.isfinite(x[ch, s * step : s * step + 512]).all()  # noqa: E731
                                      for s in range((x.shape[1] - 512) // step + 1)])
        k24 = int((seg_ok(2) & seg_ok(4)).sum())
        assert G.n_averages[2, 4] == k24 and G.n_averages[0, 0] == (x.shape[1] - 512) // step + 1
        keep = seg_ok(2) & seg_ok(1)
        p = np.mean([ss.csd(x[2, s * step : s * step + 512], x[1, s * step : s * step + 512], FS, nperseg=512)[1]
                     for s in np.flatnonzero(keep)], axis=0)
        tol = 1e-5 if kw.get("dtype") == "float32" else 1e-11
        np.testing.assert_allclose(G.G[:, 2, 1], p, rtol=0, atol=tol * np.abs(p).max())


def test_working_memory_does_not_grow_with_the_record():
    """tracemalloc peak of one pass (the input excluded) at 2e5 and 2e6 samples: within 1.2× on one
    thread, and under 50 MB with two (issue #9 target 2; benchmarks/scaling.py measures 1e6 against
    1e8). Each thread holds its own blocks, so the peak scales with the threads, not the length."""
    x = RNG.standard_normal((4, 2_000_000))
    csd_matrix(x[:, :20_000], FS, nperseg=4096)

    def peak(n, workers):
        tracemalloc.start()
        csd_matrix(x[:, :n], FS, nperseg=4096, workers=workers)
        out = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return out

    short, long = peak(200_000, 1), peak(2_000_000, 1)
    assert long < 1.2 * short and long < 25e6
    assert peak(2_000_000, 2) < 50e6


def test_any_memory_layout_gives_scipys_matrix():
    """Rows read in place through one flat view (row-sliced, channel-strided) or copied (Fortran
    order, strided samples): the same matrix."""
    atol = 1e-13 * np.abs(REF).max()
    np.testing.assert_allclose(csd_matrix(np.asfortranarray(X), FS, **KW).G, REF, rtol=0, atol=atol)
    np.testing.assert_allclose(csd_matrix(X[::2], FS, **KW).G, REF[:, ::2, ::2], rtol=0, atol=atol)
    wide = np.repeat(X, 2, axis=1)  # every sample twice: [:, ::2] is X with a sample stride of 2
    np.testing.assert_allclose(csd_matrix(wide[:, ::2], FS, **KW).G, REF, rtol=0, atol=atol)
    tail = csd_matrix(X[1:, 7:], FS, **KW).G
    np.testing.assert_allclose(tail, _pairwise(X[1:, 7:], **KW), rtol=0, atol=atol)
