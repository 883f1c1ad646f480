"""The analysis survives missing samples and signal faults: modes of the demo model against its
exact modes, SSI covariances and decimation that never bridge a gap, the gap diagnosis on the
gap-free stretches, and gaps shown in the time-series figure and the rerun recording."""

import json
import warnings

import numpy as np
import pytest
import scipy.signal

from vibroscope.commands.analyse import report_text
from vibroscope.models import demo_model
from vibroscope.models.excitation import band_limited_random
from vibroscope.models.simulate import simulate
from vibroscope.modal.ssi import output_covariances
from vibroscope.pipeline import analyse_signals, decimate, summary_dict
from vibroscope.signals import Signals

FS = 1000.0
MODEL = demo_model()
TRUE = MODEL.modes().natural_frequencies


@pytest.fixture(scope="module")
def demo():
    """The demo's record (force then accelerations), 120 s at 1 kHz, as `vibroscope demo` makes it."""
    n = int(120 * FS)
    u = band_limited_random(FS, n, fmin=2.0, fmax=0.3 * FS, rms=20.0, seed=1)
    return simulate(MODEL, u, FS, noise=0.02, seed=2)


def _with_nan(sig, spans):
    d = np.array(sig.data)
    for ch, a, b in spans:
        d[sig.index(ch), a:b] = np.nan
    return Signals(data=d, fs=sig.fs, channels=sig.channels, units=sig.units, t0=sig.t0, meta=sig.meta)


def _assert_modes(freqs, tol):
    freqs = np.asarray(freqs)
    for f in TRUE:
        assert np.min(np.abs(freqs / f - 1)) < tol, (freqs, TRUE)


def test_frf_analysis_with_nan_in_response_and_force_gives_the_modes(demo):
    force, acc = demo.channels[0], demo.channels[2]
    sig = _with_nan(demo, [(acc, 10_000, 10_010), (force, 60_000, 60_001), (acc, 90_500, 90_700)])
    an = analyse_signals(sig, input=force)
    assert len(an.modal.natural_frequencies) == len(TRUE)
    _assert_modes(an.modal.natural_frequencies, 5e-3)
    kinds = sorted((f.channel, f.kind) for f in an.faults)
    assert kinds == [(force, "nan"), (acc, "nan")]
    assert any("missing samples (NaN)" in w and acc in w for w in an.warnings)
    n_seg, n_avg = an.settings["n_segments"], an.settings["n_averages"]
    assert n_avg < n_seg
    assert any(f"{n_avg} of {n_seg} Welch segments averaged" in w for w in an.warnings)
    assert np.all(np.isfinite(an.frf.H[1:]))
    doc = json.loads(json.dumps(summary_dict(an)))
    assert [d["kind"] for d in doc["faults"]] == ["nan", "nan"]
    assert doc["faults"][1]["spans"] == [[10_000, 10_010], [90_500, 90_700]]
    text = report_text(an, source="demo")
    assert f"{n_avg} of {n_seg} averages" in text
    assert [ln for ln in text.splitlines() if "fault" in ln] == [
        "  faults: 2 nan (details: --verbose or --json)"]
    text = report_text(an, source="demo", verbose=True)
    nan_lines = [ln for ln in text.splitlines() if ln.startswith("  fault: nan in ")]
    assert len(nan_lines) == 1 and nan_lines[0].startswith(f"  fault: nan in 2 channels ({force}, {acc}); e.g. ")


def test_output_only_ssi_with_nan_gives_the_modes(demo):
    out = demo.select(MODEL.output_channels())
    sig = _with_nan(out, [(out.channels[1], 10_000, 10_010), (out.channels[0], 50_000, 52_000),
                          (out.channels[2], 90_000, 90_001)])
    an = analyse_signals(sig, fmax=100.0)
    assert an.modal.method.startswith("ssi")
    _assert_modes(an.modal.natural_frequencies, 1e-2)


def test_clipped_and_dropped_out_response_is_masked_not_analysed(demo):
    force, acc = demo.channels[0], demo.channels[1]
    d = np.array(demo.data)
    k = demo.index(acc)
    d[k, 20_000:20_500] = 0.0  # dropout
    rail = np.quantile(d[k], 0.9995)
    d[k] = np.minimum(d[k], rail)  # clipped at the top
    sig = Signals(data=d, fs=demo.fs, channels=demo.channels, units=demo.units)
    an = analyse_signals(sig, input=force)
    kinds = {f.kind for f in an.faults if f.channel == acc}
    assert {"dropout", "clipping"} <= kinds
    masked = np.isnan(an.signals[acc]) if an.signals.fs == FS else None
    if masked is not None:
        assert masked[20_000:20_500].all()
    _assert_modes(an.modal.natural_frequencies, 5e-3)


def test_fatal_faults_stop_naming_the_channel(demo):
    force = demo.channels[0]
    sig = _with_nan(demo, [(demo.channels[3], 0, demo.n_samples)])
    with pytest.raises(ValueError, match=r"nan in /imu/m3\S*: every sample is missing"):
        analyse_signals(sig, input=force)
    d = np.array(demo.data)
    d[0] = 0.0
    with pytest.raises(ValueError, match=r"zero_input in /actuator/force\S*: .*without --input"):
        analyse_signals(Signals(data=d, fs=demo.fs, channels=demo.channels, units=demo.units), input=force)
    with pytest.raises(ValueError, match=r"fmin=50.0 Hz must not exceed fmax=10.0 Hz"):
        analyse_signals(demo, input=force, fmin=50.0, fmax=10.0)


def test_output_covariances_over_present_pairs_only():
    rng = np.random.default_rng(0)
    y = rng.standard_normal((2, 400))
    y[0, 50:60] = np.nan
    y[1, 300] = np.nan
    R = output_covariances(y, 5)
    for i in range(5):
        for a in range(2):
            for b in range(2):
                p = y[a, i:] * y[b, : 400 - i]
                ok = np.isfinite(p)
                assert R[i, a, b] == pytest.approx(p[ok].sum() / ok.sum(), rel=1e-12)
    clean = rng.standard_normal((2, 400))
    R0 = output_covariances(clean, 3)
    assert R0[2, 0, 1] == pytest.approx(clean[0, 2:] @ clean[1, :398] / 398, rel=1e-12)


def test_decimate_never_filters_across_a_gap():
    rng = np.random.default_rng(1)
    x = rng.standard_normal((1, 40_000))
    x[0, 15_003:15_100] = np.nan
    sig = Signals(data=x, fs=1000.0, channels=["/a"])
    out = decimate(sig, 40.0)  # factor 10
    assert out.fs == 100.0 and out.n_samples == 4000
    y = out.data[0]
    # the stretch before the gap, decimated as a record of its own
    sos = scipy.signal.cheby1(9, 0.05, 0.8 / 10, output="sos")

    def dec(v):
        return scipy.signal.sosfiltfilt(sos, v)[::10]

    np.testing.assert_allclose(y[:1501], dec(x[0, :15_003]), rtol=0, atol=1e-12)
    assert np.isnan(y[1501:1510]).all()  # grid points 15010..15090 lie in the gap
    a = 15_100  # next stretch starts on the grid (a multiple of 10)
    np.testing.assert_allclose(y[a // 10:], dec(x[0, a:]), atol=1e-12)


def test_gap_diagnosis_splits_at_gaps_or_stops_naming_the_channel(demo):
    from vibroscope.gap.diagnosis import _split_at_gaps

    sig = _with_nan(demo, [(demo.channels[2], 40_000, 40_050), (demo.channels[0], 115_000, 115_001)])
    with pytest.warns(UserWarning, match=r"diagnosed as 2 gap-free stretches"):
        parts = _split_at_gaps(MODEL, [sig], None)
    assert [p.meta["stretch"] for p in parts] == [[0, 40_000], [40_050, 115_000]]  # the 5 s tail < 8 s
    np.testing.assert_array_equal(parts[1].data, demo.data[:, 40_050:115_000])
    assert parts[1].t0 == pytest.approx(demo.t0 + 40.05)
    from vibroscope.gap import diagnose

    bad = _with_nan(demo, [(demo.channels[1], k, k + 1) for k in range(0, demo.n_samples, 5000)])
    with pytest.raises(ValueError, match=r"channel\(s\) \['/imu/m1\S*'\].*longest stretch"):
        diagnose(MODEL, bad)


def test_gap_diagnosis_runs_on_the_stretches_of_a_log_with_a_gap():
    """The demo model against its own simulation with a 0.1 s gap: no gap found (verdict none,
    the error at the 2 % noise level), the log diagnosed as two stretches."""
    from vibroscope.gap import diagnose

    fs = 500.0
    u = band_limited_random(fs, int(60 * fs), fmin=2.0, fmax=0.3 * fs, rms=20.0, seed=1)
    sig = _with_nan(simulate(MODEL, u, fs, noise=0.02, seed=2), [("/imu/m2.linear_acceleration.x", 14_000, 14_050)])
    with pytest.warns(UserWarning, match=r"diagnosed as 2 gap-free stretches \(29950 of 30000 samples"):
        rep = diagnose(MODEL, sig, workers=1)
    assert rep.verdict == "none" and rep.gap_before < 0.05


def test_time_series_figure_shades_the_gaps():
    import matplotlib

    matplotlib.use("Agg")
    from vibroscope.viewers.figures import plot_signals

    x = np.random.default_rng(2).standard_normal((2, 20_000))
    x[0, 5000:6500] = np.nan
    x[0, 15_000] = np.inf
    x[1, 12_000:12_010] = np.nan
    fig = plot_signals(Signals(data=x, fs=100.0, channels=["/a", "/b"], units=["m/s^2", "m/s^2"]))
    a0, a1 = fig.axes[:2]
    spans0 = [p.get_x() for p in a0.patches]
    assert len(a0.patches) == 2 and len(a1.patches) == 1
    assert spans0[0] == pytest.approx(50.0) and a0.patches[0].get_width() == pytest.approx(15.0)
    assert a0.get_legend().get_texts()[0].get_text() == "gap (no data)"
    assert "; 2 gaps without data, shaded" in fig._suptitle.get_text()  # the most in one channel
    clean = plot_signals(Signals(data=x[:, :4000], fs=100.0, channels=["/a", "/b"]))
    assert all(len(ax.patches) == 0 for ax in clean.axes)


def test_rerun_breaks_the_series_and_logs_each_gap(tmp_path):
    pytest.importorskip("rerun")
    from vibroscope.viewers.rerun_view import log_analysis, read_rrd

    x = np.random.default_rng(3).standard_normal((2, 1000))
    x[0, 100:110] = np.nan
    x[0, 500] = np.inf
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log_analysis(signals=Signals(data=x, fs=100.0, channels=["/imu.x", "/imu.y"], units=["m/s^2"] * 2),
                     rrd_path=tmp_path / "g.rrd")
    d = read_rrd(tmp_path / "g.rrd")
    vals = np.asarray(d["/signals/imu.x"]["Scalars:scalars"], float).ravel()
    assert vals.size == 989 and np.isfinite(vals).all()  # the 11 missing samples are not sent
    assert len(d["/signals/imu.x"]["Clear:is_recursive"]) == 2
    assert d["/signals/gaps"]["TextLog:text"] == ["gap (no data) in /imu.x: 1–1.1 s (10 samples)",
                                                  "gap (no data) in /imu.x: 5–5.01 s (1 samples)"]
    assert np.asarray(d["/signals/imu.y"]["Scalars:scalars"]).size == 1000


@pytest.mark.parametrize("n, n_lags, ref", [(150_001, 169, None), (70_000, 300, [2, 0]), (1000, 1000, [1]),
                                            (5000, 31, None), (257, 40, [0])])
def test_output_covariances_by_fft_equal_the_direct_sums(n, n_lags, ref):
    """The sectioned FFT (blocks, a record that is not a whole number of them, every lag up to the
    record's length, a reference subset in another order) against ``Σ_k y[k+i] y_ref[k] / (n − i)``."""
    rng = np.random.default_rng(n)
    y = rng.standard_normal((3, n)) + np.array([[0.5], [0.0], [-2.0]])
    yr = y if ref is None else y[ref]
    R = output_covariances(y, n_lags, ref)
    assert R.shape == (n_lags, 3, yr.shape[0])
    scale = np.abs(R[0]).max()
    for i in (0, 1, n_lags // 2, n_lags - 1):
        direct = y[:, i:] @ yr[:, : n - i].T / (n - i)
        np.testing.assert_allclose(R[i], direct, rtol=0, atol=1e-13 * scale)
    with pytest.raises(ValueError, match="n_lags=0 must be between 1 and the record length n=257"):
        output_covariances(y[:, :257], 0)
