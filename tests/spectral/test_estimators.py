"""Spectral estimators against scipy and against analytic truth."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as ss

from vibroscope import Signals
from vibroscope.spectral import (
    Coherence,
    CrossSpectralAccumulator,
    MultipleCoherence,
    amplitude_spectrum,
    coherence,
    csd_matrix,
    frf,
    multiple_coherence,
    segment_settings,
    spectrogram,
    welch,
)

RNG = np.random.default_rng(20261121)
X = RNG.standard_normal((4, 12_345))
FS = 512.0

SETTINGS = [
    dict(nperseg=256),
    dict(nperseg=300, noverlap=100, window=("tukey", 0.3), detrend="linear"),
    dict(nperseg=255, nfft=512, window="flattop"),
    dict(nperseg=128, noverlap=0, detrend=False, scaling="spectrum"),
    dict(nperseg=1000, window="boxcar"),
]


@pytest.mark.parametrize("kw", SETTINGS)
def test_csd_matrix_parity_with_scipy(kw):
    G = csd_matrix(X, FS, **kw)
    for i in range(4):
        for j in range(4):
            f, p = ss.csd(X[i], X[j], FS, **kw)
            np.testing.assert_allclose(G.G[:, i, j], p, rtol=1e-10, atol=1e-14 * np.abs(p).max())
    np.testing.assert_allclose(G.frequencies, f)
    # Hermitian, real non-negative diagonal
    np.testing.assert_allclose(G.G, np.conj(G.G.transpose(0, 2, 1)), atol=1e-15)


@pytest.mark.parametrize("kw", SETTINGS)
def test_welch_parity_with_scipy(kw):
    f, p = ss.welch(X, FS, **kw)
    s = welch(X, FS, **kw)
    np.testing.assert_allclose(s.values, p, rtol=1e-10, atol=1e-14 * p.max())
    np.testing.assert_allclose(s.frequencies, f)
    assert s.settings["n_averages"] > 0


@pytest.mark.parametrize("kw", [d for d in SETTINGS if "scaling" not in d])
def test_coherence_parity_with_scipy(kw):
    f, g2 = coherence(X, FS, **kw)
    for i, j in [(0, 1), (2, 3), (1, 3)]:
        _, c = ss.coherence(X[i], X[j], FS, **kw)
        # the DC bin after mean removal is round-off over round-off in both: skip it
        np.testing.assert_allclose(g2[1:, i, j], c[1:], rtol=1e-10, atol=1e-13)


def test_streaming_and_threads_equal_single_pass():
    ref = csd_matrix(X, FS, nperseg=256).G
    st = segment_settings(None, nperseg=256, noverlap=128, window="hann", detrend="constant")
    acc = CrossSpectralAccumulator(4, FS, st)
    for k in range(0, X.shape[1], 777):
        acc.update(X[:, k : k + 777])
    np.testing.assert_allclose(acc.result(), ref, rtol=1e-12, atol=1e-18)
    big = RNG.standard_normal((3, 200_000))
    np.testing.assert_allclose(csd_matrix(big, FS, nperseg=256, workers=2).G,
                               csd_matrix(big, FS, nperseg=256).G, rtol=1e-12, atol=1e-18)


def test_accumulators_merge_like_one_record_of_segments():
    st = segment_settings(None, nperseg=256, noverlap=0, window="hann", detrend="constant")
    a = CrossSpectralAccumulator(4, FS, st).update(X[:, :256 * 20])
    b = CrossSpectralAccumulator(4, FS, st).update(X[:, 256 * 20 : 256 * 40])
    whole = CrossSpectralAccumulator(4, FS, st).update(X[:, : 256 * 40])
    np.testing.assert_allclose(a.merge(b).result(), whole.result(), rtol=1e-12)
    assert a.n_segments == 40


@pytest.mark.parametrize("window", ["hann", "hamming", "flattop", "blackmanharris", "boxcar", ("kaiser", 8)])
def test_sine_peak_is_a_squared_over_two(window):
    """A sine of amplitude A on a bin peaks at A²/2 in the power spectrum for any window
    (scipy's TestWelch.test_window_correction); the density integrates to the mean square."""
    fs, A, n = 1000.0, 3.0, 50_000
    t = np.arange(n) / fs
    x = A * np.sin(2 * np.pi * 125.0 * t)
    ps = welch(x, fs, nperseg=1000, window=window, scaling="spectrum")
    # exact for windows whose spectrum vanishes at the image (-125 Hz); Kaiser leaks ~1e-6
    assert ps.values[0].max() == pytest.approx(A**2 / 2, rel=1e-5)
    assert ps.frequencies[np.argmax(ps.values[0])] == 125.0
    psd = welch(x, fs, nperseg=1000, window=window)
    assert psd.rms()[0] == pytest.approx(A / np.sqrt(2), rel=1e-6)


def test_parseval_on_white_noise():
    """One-sided density integrates to the variance (Parseval), exactly for a boxcar without overlap."""
    x = RNG.standard_normal(2**16)
    p = welch(x, 1.0, nperseg=2**16, window="boxcar", detrend=False)
    assert np.sum(p.values[0]) * p.df == pytest.approx(np.mean(x**2), rel=1e-12)


def test_amplitude_spectrum_reads_the_amplitude():
    fs, n = 2048.0, 8192
    t = np.arange(n) / fs
    x = 0.7 * np.cos(2 * np.pi * 64.0 * t + 0.3) + 2.5 * np.sin(2 * np.pi * 300.0 * t)
    a = amplitude_spectrum(x, fs)
    assert a.scaling == "amplitude"
    assert a.values[0][a.frequencies == 64.0][0] == pytest.approx(0.7, rel=1e-9)
    assert a.values[0][a.frequencies == 300.0][0] == pytest.approx(2.5, rel=1e-9)
    # between bins the flat-top window keeps the amplitude within 0.1 %
    x2 = 1.2 * np.sin(2 * np.pi * 100.125 * t)
    af = amplitude_spectrum(x2, fs, window="flattop")
    assert af.values[0].max() == pytest.approx(1.2, rel=2e-3)


def _fir_system(n, noise_in=0.0, noise_out=0.0, seed=0):
    """x → lfilter(b, a) → y with known exact FRF from freqz."""
    rng = np.random.default_rng(seed)
    b, a = ss.butter(2, [0.1, 0.3], btype="bandpass")
    b = b + 0.2 * np.r_[1, np.zeros(b.size - 1)]  # keep |H| away from 0 everywhere
    u = rng.standard_normal(n)
    y = ss.lfilter(b, a, u)
    x_meas = u + noise_in * rng.standard_normal(n)
    y_meas = y + noise_out * rng.standard_normal(n)
    return np.vstack([x_meas, y_meas]), b, a


def _true_H(b, a, f, fs):
    _, h = ss.freqz(b, a, worN=f, fs=fs)
    return h


def test_h1_h2_hv_equal_truth_without_noise():
    data, b, a = _fir_system(2**17)
    for est in ("H1", "H2", "Hv"):
        h = frf(data, 0, 1, fs=1.0, nperseg=1024, estimator=est)
        Ht = _true_H(b, a, h.frequencies, 1.0)
        sel = h.coherence[:, 0] > 0.99
        assert sel.mean() > 0.99
        # measured: |H| within 0.93 % (H2), phase within 0.133° (all three), on every line
        np.testing.assert_allclose(np.abs(h.H[sel, 0, 0]), np.abs(Ht[sel]), rtol=0.015)
        dphi = np.degrees(np.angle(h.H[sel, 0, 0] / Ht[sel]))
        assert np.max(np.abs(dphi)) < 0.25


def test_textbook_bias_noise_on_output_only():
    """Bendat & Piersol §9.1: output noise leaves H1 unbiased and biases H2 high."""
    data, b, a = _fir_system(2**18, noise_out=1.0, seed=1)
    h1 = frf(data, 0, 1, fs=1.0, nperseg=512, estimator="H1")
    h2 = frf(data, 0, 1, fs=1.0, nperseg=512, estimator="H2")
    hv = frf(data, 0, 1, fs=1.0, nperseg=512, estimator="Hv")
    Ht = np.abs(_true_H(b, a, h1.frequencies, 1.0))
    r1 = np.abs(h1.H[:, 0, 0]) / Ht
    r2 = np.abs(h2.H[:, 0, 0]) / Ht
    rv = np.abs(hv.H[:, 0, 0]) / Ht
    band = (h1.frequencies > 0.02) & (h1.frequencies < 0.48)
    assert np.median(r1[band]) == pytest.approx(1.0, abs=0.02)
    assert np.median(r2[band]) > 1.1
    # expected bias of H2: 1 + Gnn/Gyy
    assert np.all(r1[band] <= rv[band] * (1 + 1e-9)) and np.all(rv[band] <= r2[band] * (1 + 1e-9))


def test_textbook_bias_noise_on_input_only():
    """Bendat & Piersol §9.1: input noise biases H1 low and leaves H2 unbiased."""
    data, b, a = _fir_system(2**18, noise_in=0.7, seed=2)
    h1 = frf(data, 0, 1, fs=1.0, nperseg=512, estimator="H1")
    h2 = frf(data, 0, 1, fs=1.0, nperseg=512, estimator="H2")
    Ht = np.abs(_true_H(b, a, h1.frequencies, 1.0))
    band = (h1.frequencies > 0.02) & (h1.frequencies < 0.48)
    r1 = (np.abs(h1.H[:, 0, 0]) / Ht)[band]
    r2 = (np.abs(h2.H[:, 0, 0]) / Ht)[band]
    # H1 = H / (1 + Gmm/Guu) with white input noise of variance 0.49: ratio 1/1.49
    assert np.median(r1) == pytest.approx(1 / 1.49, rel=0.03)
    assert np.median(r2) == pytest.approx(1.0, abs=0.02)


def test_two_input_h1_and_multiple_coherence():
    """Two uncorrelated inputs through known filters: H1 separates them; the multiple coherence is
    1 without noise, while each ordinary coherence is only the fraction of power from its input."""
    n = 2**17
    rng = np.random.default_rng(3)
    u1, u2 = rng.standard_normal((2, n))
    b1, a1 = ss.butter(2, 0.2)
    b2, a2 = ss.butter(2, 0.3, btype="high")
    y = ss.lfilter(b1, a1, u1) + ss.lfilter(b2, a2, u2)
    data = np.vstack([u1, u2, y])
    h = frf(data, [0, 1], [2], fs=1.0, nperseg=512)
    f = h.frequencies
    sel = (f > 0.01) & (f < 0.49)
    for k, (b, a) in enumerate([(b1, a1), (b2, a2)]):
        Ht = _true_H(b, a, f, 1.0)
        err = np.abs(h.H[sel, 0, k] - Ht[sel])
        assert np.max(err) < 0.03
    _, mc = multiple_coherence(data, [0, 1], [2], fs=1.0, nperseg=512)
    assert np.min(mc[sel, 0]) > 0.999
    _, g2 = coherence(data, 1.0, nperseg=512)
    assert np.median(g2[sel, 0, 2]) < 0.9


def test_frf_kind_and_conversion_from_units():
    fs = 1000.0
    data, *_ = _fir_system(2**14)
    sig = Signals(data=data, fs=fs, channels=["/f.wrench.force.x", "/imu.linear_acceleration.x"], units=["N", "m/s^2"])
    h = frf(sig, "/f.wrench.force.x", nperseg=256)
    assert h.kind == "accelerance" and h.units == "m/s^2/N"
    assert h.outputs == ("/imu.linear_acceleration.x",)
    rec = h.to("receptance")
    w = 2 * np.pi * h.frequencies[1:]
    np.testing.assert_allclose(rec.H[1:, 0, 0], -h.H[1:, 0, 0] / w**2)
    assert np.isnan(rec.H[0, 0, 0])
    mob = h.to("mobility")
    np.testing.assert_allclose(mob.to("accelerance").H[1:], h.H[1:])


def test_errors_are_clear():
    with pytest.raises(ValueError, match="nperseg=2048 must not exceed the record length n=1000"):
        welch(np.zeros(1000), 1.0, nperseg=2048)
    with pytest.raises(ValueError, match="noverlap"):
        csd_matrix(np.zeros((2, 1000)), 1.0, nperseg=100, noverlap=100)
    with pytest.raises(ValueError, match="'estimator' parameter"):
        frf(np.zeros((2, 1000)), 0, 1, estimator="H3")
    with pytest.raises(ValueError, match="both input and output"):
        frf(np.zeros((2, 1000)), 0, [0, 1])
    with pytest.raises(KeyError, match="no channel"):
        frf(Signals(data=np.zeros((2, 1000)), fs=10.0, channels=["a", "b"]), "c")


def test_results_are_read_only_and_unpack():
    s = welch(X, FS, nperseg=256)
    f, p = s
    with pytest.raises(ValueError):
        p[0, 0] = 1.0
    G = csd_matrix(X, FS, nperseg=256)
    psd = G.psd()
    np.testing.assert_allclose(psd.values, s.values, rtol=1e-12)
    sub = G.select([2, 0])
    np.testing.assert_allclose(sub.G[:, 0, 1], G.G[:, 2, 0])


def test_spectrogram_matches_scipy():
    sg = spectrogram(X[:2], FS, nperseg=128)
    f, t, S = ss.spectrogram(X[:2], FS, window="hann", nperseg=128, noverlap=64)
    np.testing.assert_allclose(sg.values, S, rtol=1e-12)
    np.testing.assert_allclose(sg.times, t)


@pytest.mark.parametrize("setting, other", [
    ("window", dict(window="hamming")),
    ("noverlap", dict(noverlap=64)),
    ("detrend", dict(detrend="linear")),
    ("nperseg", dict(nperseg=128, noverlap=64)),
])
def test_merge_refuses_accumulators_of_other_settings(setting, other):
    """Averaging segments of different windows, overlaps or detrending is no Welch estimate."""
    kw = dict(nperseg=256, noverlap=128, window="hann", detrend="constant")
    a = CrossSpectralAccumulator(4, FS, segment_settings(None, **kw)).update(X[:, :4096])
    b = CrossSpectralAccumulator(4, FS, segment_settings(None, **{**kw, **other})).update(X[:, 4096:8192])
    with pytest.raises(ValueError, match=f"different {setting}"):
        a.merge(b)
    assert a.n_segments == 31  # untouched


def test_every_channel_lookup_raises_one_key_error_naming_the_channels():
    sig = Signals(data=X[:2], fs=FS, channels=["a", "b"])
    s = welch(sig, nperseg=256)
    G = csd_matrix(sig, nperseg=256)
    np.testing.assert_array_equal(s["b"], s.values[1])
    np.testing.assert_array_equal(s[-1], s.values[1])
    assert G.index(-1) == 1 and G.index("a") == 0
    for lookup in (lambda: s["x"], lambda: s[2], lambda: G.index(5), lambda: G.index("x"),
                   lambda: G.select(["a", 7]), lambda: frf(G, "a", 9)):
        with pytest.raises(KeyError, match=r"no channel .*channels are \['a', 'b'\]"):
            lookup()


def test_h1_h2_are_what_the_docstring_says():
    """``H1 = Gxy / Gxx`` and ``H2 = Gyy / Gyx`` with ``Gxy = E[conj(X) Y]`` (scipy's csd)."""
    data, *_ = _fir_system(2**14, noise_out=0.3)
    G = csd_matrix(data, 1.0, nperseg=256)
    g = G.G
    np.testing.assert_allclose(frf(G, 0, 1, estimator="H1").H[:, 0, 0], g[:, 0, 1] / g[:, 0, 0], rtol=1e-12)
    np.testing.assert_allclose(frf(G, 0, 1, estimator="H2").H[:, 0, 0], g[:, 1, 1] / g[:, 1, 0], rtol=1e-12)
    _, pxy = ss.csd(data[0], data[1], 1.0, nperseg=256)
    np.testing.assert_allclose(g[:, 0, 1], pxy, rtol=1e-10)
    doc = " ".join(frf.__doc__.split())
    assert "H1 = Gxy / Gxx" in doc and "H2 = Gyy / Gyx" in doc
    assert "H1 = Gxy/Gxx, H2 = Gyy/Gyx" in doc  # the Notes say the same


def test_amplitude_spectrum_keeps_the_offset_without_detrend():
    """With ``detrend=False`` the 0 Hz line reads a DC offset, like scipy's periodogram; the
    default removes it."""
    fs, n = 1024.0, 4096
    t = np.arange(n) / fs
    x = 1.5 + 0.8 * np.sin(2 * np.pi * 64.0 * t)
    f, p = ss.periodogram(x, fs, window="hann", detrend=False, scaling="spectrum")
    a = amplitude_spectrum(x, fs, detrend=False)
    np.testing.assert_allclose(a.frequencies, f)
    expect = np.sqrt(p)
    expect[1:-1] *= np.sqrt(2.0)  # peak amplitude: sqrt(2) × RMS except at DC and Nyquist
    np.testing.assert_allclose(a.values[0], expect, rtol=1e-10, atol=1e-12)
    assert a.values[0, 0] == pytest.approx(1.5, rel=1e-12)
    assert a.values[0][f == 64.0][0] == pytest.approx(0.8, rel=1e-12)
    assert a.settings["detrend"] is False
    assert amplitude_spectrum(x, fs).values[0, 0] == pytest.approx(0.0, abs=1e-12)


def test_coherences_are_results_that_unpack_like_tuples():
    sig = Signals(data=X[:3], fs=FS, channels=["a", "b", "c"])
    c = coherence(sig, nperseg=256)
    assert isinstance(c, Coherence) and c.channels == ("a", "b", "c") and c.settings["nperseg"] == 256
    f, g2 = c
    assert len(c) == 2 and c[0] is f and c[1] is g2 and g2.shape == (129, 3, 3)
    with pytest.raises(ValueError):
        g2[0, 0, 0] = 0.5
    m = multiple_coherence(sig, ["a", "b"], "c", nperseg=256)
    assert isinstance(m, MultipleCoherence) and m.inputs == ("a", "b") and m.outputs == ("c",)
    f2, mc = m
    np.testing.assert_array_equal(f2, f)
    assert mc.shape == (129, 1) and np.all(mc[1:] >= np.max(g2[1:, :2, 2], axis=1)[:, None] - 1e-12)


def test_results_print_a_summary_not_arrays():
    sig = Signals(data=X[:3], fs=FS, channels=["a", "b", "c"])
    G = csd_matrix(sig, nperseg=256)
    results = [welch(sig, nperseg=256), G, frf(G, "a"), coherence(G), multiple_coherence(G, "a"),
               spectrogram(sig, nperseg=256)]
    for r in results:
        text = repr(r)
        assert text.startswith(type(r).__name__ + "(") and "array" not in text and len(text) < 200, text
    assert repr(G) == "CrossSpectralMatrix(3×3 channels ['a', 'b', 'c'], 129 lines, 0–256 Hz, scaling='density')"
