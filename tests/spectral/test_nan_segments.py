"""Welch / csd_matrix / FRF with missing samples: segments touching NaN/Inf are skipped per pair,
each pair normalised by its own count; hostile options fail with a clear message."""

import warnings

import numpy as np
import pytest
import scipy.signal

from vibroscope.signals import Signals
from vibroscope.spectral import csd_matrix, frf, welch
from vibroscope.spectral.estimators import FewAveragesWarning

NPER = 128


def _record(seed=0, n=NPER * 40):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((3, n))


def _valid_segments(x, nper):
    """Indices of the non-overlapping segments of a 1-D record that are all finite."""
    k = x.size // nper
    return [s for s in range(k) if np.all(np.isfinite(x[s * nper:(s + 1) * nper]))]


def _concat(x, segs, nper):
    return np.concatenate([x[s * nper:(s + 1) * nper] for s in segs])


def test_nan_spans_equal_scipy_on_the_valid_segments():
    x = _record()
    x[0, 300:310] = np.nan            # segment 2
    x[0, 1000] = np.inf               # segment 7 (Inf is missing too)
    x[1, 2000:2600] = np.nan          # segments 15..20
    x[2, 127] = -np.inf               # segment 0
    G = csd_matrix(x, fs=100.0, nperseg=NPER, noverlap=0)
    p = welch(x, fs=100.0, nperseg=NPER, noverlap=0)
    n_seg = x.shape[1] // NPER
    assert G.settings["n_segments"] == n_seg
    for i in range(3):
        si = set(_valid_segments(x[i], NPER))
        assert p.n_averages[i] == len(si)
        _, ref = scipy.signal.welch(_concat(x[i], sorted(si), NPER), fs=100.0, nperseg=NPER, noverlap=0)
        np.testing.assert_allclose(p.values[i], ref, rtol=1e-12, atol=0)
        for j in range(3):
            both = sorted(si & set(_valid_segments(x[j], NPER)))
            assert G.n_averages[i, j] == len(both)
            _, ref = scipy.signal.csd(_concat(x[i], both, NPER), _concat(x[j], both, NPER), fs=100.0,
                                      nperseg=NPER, noverlap=0)
            np.testing.assert_allclose(G.G[:, i, j], ref, rtol=1e-12, atol=1e-15)
    # counted by hand: channel 0 loses segments 2 and 7, channel 1 loses 15..20, channel 2 loses 0
    assert list(p.n_averages) == [n_seg - 2, n_seg - 6, n_seg - 1]
    assert G.n_averages[0, 1] == n_seg - 8 and G.n_averages[0, 2] == n_seg - 3
    assert G.settings["n_averages"] == n_seg - 8
    assert np.all(np.isfinite(G.G))


def test_overlapping_segments_and_linear_detrend_match_scipy_segmentwise():
    """With 50 % overlap a NaN removes the two segments that hold it; detrend='linear' too."""
    x = _record(1)
    x[1, 700] = np.nan
    step = NPER // 2
    G = csd_matrix(x, fs=1.0, nperseg=NPER, detrend="linear")
    n_seg = (x.shape[1] - NPER) // step + 1
    starts = [s * step for s in range(n_seg) if not (s * step <= 700 < s * step + NPER)]
    assert G.n_averages[1, 1] == n_seg - 2 and G.n_averages[0, 0] == n_seg
    # scipy over the same segment set: average of the per-segment estimates
    ref = np.mean([scipy.signal.csd(x[0, a:a + NPER], x[1, a:a + NPER], nperseg=NPER, detrend="linear")[1]
                   for a in starts], axis=0)
    np.testing.assert_allclose(G.G[:, 0, 1], ref, rtol=1e-12, atol=1e-15)


def test_nan_free_result_unchanged_and_counts_full():
    x = _record(2)
    G = csd_matrix(x, fs=10.0, nperseg=NPER)
    _, ref = scipy.signal.csd(x[0], x[2], fs=10.0, nperseg=NPER)
    np.testing.assert_allclose(G.G[:, 0, 2], ref, rtol=1e-12)
    n_seg = (x.shape[1] - NPER) // (NPER // 2) + 1
    assert np.all(G.n_averages == n_seg) and "n_segments" not in G.settings
    assert G.select([2, 0]).n_averages.shape == (2, 2)
    assert G.psd().n_averages.tolist() == [n_seg] * 3


def test_workers_split_gives_the_same_counts():
    x = _record(3, n=NPER * 300)
    x[0, 5000:5050] = np.nan
    a = csd_matrix(x, fs=1.0, nperseg=NPER)
    b = csd_matrix(x, fs=1.0, nperseg=NPER, workers=2)
    np.testing.assert_array_equal(a.n_averages, b.n_averages)
    np.testing.assert_allclose(a.G, b.G, rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("common", [True, False])
def test_frf_with_nan_uses_pair_counts_and_recovers_the_gain(common):
    """NaN at the same times in input and output: the exact gain; at different times the entries
    come from different segment sets (documented), still close."""
    rng = np.random.default_rng(4)
    u = rng.standard_normal(NPER * 64)
    y = 3.0 * u + 0.01 * rng.standard_normal(u.size)
    y[1000:1010] = np.nan
    u[7000] = np.nan
    if common:
        u[1000:1010] = np.nan
        y[7000] = np.nan
    sig = Signals(data=np.vstack([u, y]), fs=100.0, channels=["f", "a"], units=["N", "m/s^2"])
    n_seg = (u.size - NPER) // (NPER // 2) + 1
    for est in ("H1", "H2", "Hv"):
        h = frf(sig, "f", "a", estimator=est, nperseg=NPER)
        assert np.all(np.isfinite(h.H))
        np.testing.assert_allclose(np.abs(h.H[:, 0, 0]), 3.0, rtol=1e-3 if common else 6e-2)
        assert h.settings["n_averages"] == n_seg - 4


def test_all_nan_channel_and_disjoint_pairs_raise_naming_the_channel():
    x = _record(5)
    x[1] = np.nan
    with pytest.raises(ValueError, match=r"channel '1' has no segment.*shorter nperseg"):
        csd_matrix(x, fs=1.0, nperseg=NPER)
    with pytest.raises(ValueError, match=r"channel '1'"):
        welch(x, fs=1.0, nperseg=NPER)
    x = _record(6, n=NPER * 4)
    x[0, : 2 * NPER] = np.nan
    x[1, 2 * NPER:] = np.nan
    with pytest.raises(ValueError, match=r"channels '0' and '1' have no common segment"):
        csd_matrix(x, fs=1.0, nperseg=NPER, noverlap=0)


def test_few_averages_warn_and_none_skipped_do_not():
    x = _record(7, n=NPER * 8)
    x[0, 5] = np.nan
    with pytest.warns(FewAveragesWarning, match=r"only 7 averages remain for channel '0'.*shorter nperseg"):
        welch(x, fs=1.0, nperseg=NPER, noverlap=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        welch(_record(7, n=NPER * 4), fs=1.0, nperseg=NPER, noverlap=0)  # 4 averages, nothing skipped


@pytest.mark.parametrize("fn", [welch, csd_matrix])
def test_complex_input_is_refused(fn):
    x = np.exp(2j * np.pi * 0.1 * np.arange(1024))
    with pytest.raises(TypeError, match="x must be real"):
        fn(x, fs=1.0, nperseg=128)
    with pytest.raises(TypeError, match="x must be real"):
        frf(np.vstack([x, x]), 0, 1, fs=1.0, nperseg=128)
    with pytest.raises(TypeError, match="data must be real"):
        Signals(data=x, fs=1.0, channels=["c"])


@pytest.mark.parametrize("kw, msg", [
    (dict(fs=0.0), r"fs=0\.0 must be a positive"),
    (dict(fs=-5.0), r"fs=-5\.0 must be a positive"),
    (dict(nperseg=0), r"nperseg=0 must be positive"),
    (dict(nperseg=-3), r"nperseg=-3 must be positive"),
    (dict(nperseg=12.5), r"nperseg=12\.5 must be a whole number"),
    (dict(nperseg=128, noverlap=128), r"noverlap=128 must be in \[0, nperseg=128\).*smaller noverlap"),
    (dict(nperseg=2048), r"nperseg=2048 must not exceed the record length n=1024.*shorter nperseg"),
])
def test_bad_options_name_the_setting(kw, msg):
    x = _record(8, n=1024)
    kw = dict(dict(fs=1.0), **kw)
    with pytest.raises(ValueError, match=msg):
        welch(x, **kw)
    with pytest.raises(ValueError, match=msg):
        csd_matrix(x, **kw)


def test_band_with_fmin_above_fmax_is_refused():
    G = csd_matrix(_record(9), fs=100.0, nperseg=NPER)
    with pytest.raises(ValueError, match=r"fmin=30.*fmax=10"):
        G.band(30.0, 10.0)
    assert G.band(10.0, 30.0).n_averages.shape == (3, 3)
