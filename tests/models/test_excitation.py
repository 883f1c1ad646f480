"""Excitation generators: spectra, RMS, excited lines (Pintelon & Schoukens 2012, ch. 2)."""

import numpy as np
import pytest

from vibroscope.models.excitation import (
    band_limited_random,
    impact,
    multisine,
    parse_excitation,
    sine_sweep,
    step,
)


def test_band_limited_random_band_and_rms():
    fs, n = 1000.0, 2**14
    x = band_limited_random(fs, n, fmin=20, fmax=100, rms=3.0, seed=1)
    assert x.shape == (n,)
    assert np.sqrt(np.mean(x**2)) == pytest.approx(3.0, rel=1e-12)
    f = np.fft.rfftfreq(n, 1 / fs)
    P = np.abs(np.fft.rfft(x)) ** 2
    assert P[(f < 20) | (f > 100)].sum() < 1e-20 * P.sum()
    assert np.array_equal(x, band_limited_random(fs, n, fmin=20, fmax=100, rms=3.0, seed=1))


@pytest.mark.parametrize("lines", ["all", "odd", "random_odd"])
def test_multisine_lines(lines):
    fs, n = 750.0, 8192
    x, k = multisine(fs, n, fmin=5, fmax=150, rms=50, lines=lines, seed=0)
    assert np.sqrt(np.mean(x**2)) == pytest.approx(50, rel=1e-12)
    X = np.abs(np.fft.rfft(x))
    excited = np.nonzero(X > 1e-8 * X.max())[0]
    np.testing.assert_array_equal(excited, k)
    f = k * fs / n
    assert f.min() >= 5 and f.max() <= 150
    # flat amplitude spectrum on the excited lines
    np.testing.assert_allclose(X[k], X[k][0], rtol=1e-10)
    n_band = np.count_nonzero((np.fft.rfftfreq(n, 1 / fs) >= 5) & (np.fft.rfftfreq(n, 1 / fs) <= 150))
    if lines == "all":
        assert k.size == n_band
    else:
        assert np.all(k % 2 == 1)
    if lines == "random_odd":
        n_odd = np.count_nonzero(np.arange(k.min(), k.max() + 3) % 2 == 1)
        assert k.size < n_odd and k.size >= 2 * n_odd // 3 - 1


def test_sweep_instantaneous_frequency():
    fs, n = 1000.0, 20000
    x = sine_sweep(fs, n, f0=10, f1=100, amplitude=2.0)
    assert x[0] == pytest.approx(0.0, abs=1e-12)
    assert np.max(np.abs(x)) == pytest.approx(2.0, rel=1e-3)
    # zero crossings in the first and last second give the local frequency
    zc = np.nonzero(np.diff(np.signbit(x)))[0]
    t = zc / fs
    f_start = 0.5 / np.mean(np.diff(t[t < 1.0]))
    f_end = 0.5 / np.mean(np.diff(t[t > 19.0]))
    assert f_start == pytest.approx(10 + 90 * 0.5 / 20, rel=0.03)
    assert f_end == pytest.approx(100 - 90 * 0.5 / 20, rel=0.03)
    xl = sine_sweep(fs, duration=20.0, f0=10, f1=100, kind="log")
    assert xl.shape == (n,)


def test_impact_and_step():
    fs = 10000.0
    x = impact(fs, 1000, peak=100.0, pulse=0.002, t_start=0.01)
    assert x.max() == pytest.approx(100.0, rel=1e-3)
    # area of a half-sine: 2 peak T / pi
    assert x.sum() / fs == pytest.approx(2 * 100 * 0.002 / np.pi, rel=3e-3)  # Riemann sum, 20 samples
    assert np.all(x[:100] == 0) and np.count_nonzero(x) <= 21
    s = step(fs, 100, amplitude=2.0, t_start=0.005)
    assert np.all(s[:50] == 0) and np.all(s[50:] == 2.0)


def test_parse_excitation():
    e = parse_excitation("random:fmin=1,fmax=200,rms=10")
    assert e.kind == "random" and e.params == {"fmin": 1.0, "fmax": 200.0, "rms": 10.0}
    assert parse_excitation("random:f_lo=1,f_hi=200,rms=10") == e  # the README's older keys
    with pytest.raises(ValueError, match="f_lo"):
        parse_excitation("sweep:f_lo=1")  # an alias only where its band edge is a key
    x = e.generate(1000.0, 4096, seed=3)
    assert np.sqrt(np.mean(x**2)) == pytest.approx(10)
    assert parse_excitation("multisine:fmin=1,fmax=200,lines=odd,rms=5").generate(1000.0, 4096).shape == (4096,)
    assert parse_excitation("sweep:f0=1,f1=200,amplitude=10").generate(1000.0, 4096).max() <= 10
    imp = parse_excitation("impact:peak=100,duration=0.002").generate(10000.0, 1000)
    assert imp.max() == pytest.approx(100, rel=1e-3) and np.count_nonzero(imp) <= 21
    assert parse_excitation("step:amplitude=1").generate(100.0, 10).sum() == 10
    for bad in ("noise:rms=1", "random:foo=1", "random:rms", "random:rms=abc"):
        with pytest.raises(ValueError):
            parse_excitation(bad)
    with pytest.raises(ValueError, match="fmax"):
        band_limited_random(100.0, 100, fmin=10, fmax=80)
