"""Decimation to the analysis band keeps a periodic excitation whole and says what it did.

The shaker case of issue 20: a 3-DOF lumped model (modes 5.20, 7.31, 12.30 Hz) driven by a
random-phase multisine of 8192 samples at 400 Hz, repeated. Decimating by 10 (to 40 Hz, the old
choice for the 2–15 Hz band) makes the period 819.2 samples: the period-synchronous FRF loses its
lines above ~11 Hz and the 12.3 Hz mode (it came out 0.6 % low). The factor now divides the period
(8 → 50 Hz, 1024 samples), and the console header and the JSON summary say so.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.signal

from vibroscope.commands.analyse import report_text
from vibroscope.models import LumpedModel
from vibroscope.models.excitation import band_limited_random, multisine
from vibroscope.models.simulate import simulate
from vibroscope.pipeline import analyse_signals, decimate, decimation_stages, summary_dict
from vibroscope.spectral.periodic import detect_period

FS = 400.0
PERIOD = 8192
# masses (kg), springs (N/m) and dampers (N s/m) solved for modes at 5.2, 7.3 and 12.3 Hz
# (LumpedModel.modes: 5.2026, 7.3077, 12.3020 Hz; zeta 1.2, 1.7, 2.7 %); the force on m1
MODEL = LumpedModel.chain([1.0, 0.5, 0.08], [2610.0, 1528.0, 135.0], [2.0, 1.0, 0.1], input_dof=0,
                          name="shaker 3-DOF")
TRUE = MODEL.modes().natural_frequencies
INPUT = MODEL.input_channels()[0]


def _shaker(period: int = PERIOD, periods: int = 8, seed: int = 1):
    """Force (multisine, 2–15 Hz, 1 N rms, `period` samples repeated) and the three accelerations,
    2 % output noise."""
    one, _ = multisine(FS, period, fmin=2.0, fmax=15.0, seed=seed)
    return simulate(MODEL, np.tile(one, periods), FS, noise=0.02, seed=seed + 1)


@pytest.fixture(scope="module")
def shaker():
    return _shaker()


def _assert_three_modes(freqs, rtol=5e-3):
    freqs = np.sort(np.asarray(freqs))
    assert freqs.size == 3, freqs
    np.testing.assert_allclose(freqs, TRUE, rtol=rtol)


def test_stages_divide_the_period():
    """The total factor divides the period and is a product of stages of at most 10; without a
    period, the stages are as before (``min(q, 10)``, then ``q // 10``)."""
    assert decimation_stages(400.0, 15.0, period=8192) == [8]  # q = 10; 10 does not divide 8192
    assert decimation_stages(400.0, 15.0) == [10]
    assert decimation_stages(400.0, 15.0, period=8191) == []  # a prime period: no factor fits
    assert decimation_stages(400.0, 15.0, period=3000) == [10]
    assert decimation_stages(6000.0, 60.0, period=6000) == [10, 4]  # q = 40
    assert decimation_stages(6000.0, 40.0, period=6000) == [10, 6]  # q = 60
    assert decimation_stages(6000.0, 40.0) == [10, 6]
    assert decimation_stages(4000.0, 100.0) == [10]  # q = 16: 10 only, as before
    assert decimation_stages(4000.0, 100.0, period=4096) == [8, 2]
    for fs, fmax, p in [(400.0, 15.0, 8192), (1000.0, 7.0, 6144), (1000.0, 3.0, 9000)]:
        st = decimation_stages(fs, fmax, period=p)
        assert st and p % int(np.prod(st)) == 0 and max(st) <= 10 and fs / np.prod(st) >= 2.5 * fmax


def test_periodic_record_gives_the_three_modes_and_reports_the_decimation(shaker):
    """No option: the factor 8 (400 → 50 Hz, period 1024 samples), the three modes within 0.5 %
    of the model's (measured: 0.007 % at most), the excited lines up to 15 Hz, the decision in the
    settings, the JSON summary and the console header."""
    an = analyse_signals(shaker, input=INPUT)
    dec = an.settings["decimation"]
    assert dec["factors"] == [8] and dec["fs_in"] == FS and dec["fs_out"] == an.signals.fs == 50.0
    assert "divides the input's period: 8192 → 1024 samples" in dec["reason"]
    assert an.frf.estimator == "periodic" and an.frf.settings["period_samples"] == 1024
    f_exc = an.frf.frequencies[an.frf.settings["excited_lines"]]
    assert f_exc.max() > 14.9 and np.diff(f_exc).max() < 0.05  # every line of the band, none lost
    _assert_three_modes(an.modal.natural_frequencies)
    # the same modes as LSCF on the full-rate periodic FRF
    full = analyse_signals(shaker, input=INPUT, decimation=False)
    np.testing.assert_allclose(np.sort(an.modal.natural_frequencies), np.sort(full.modal.natural_frequencies),
                               rtol=5e-3)
    doc = json.loads(json.dumps(summary_dict(an)))
    assert doc["settings"]["decimation"]["factors"] == [8] and doc["decimated"]["fs_out"] == 50.0
    header = report_text(an, source="shaker.mcap").splitlines()[0]
    assert "decimated 400 → 50 Hz (factor 8" in header and "8192 → 1024 samples" in header


def test_period_no_factor_divides_is_not_decimated():
    """A prime period (8191 samples): no factor fits, the record stays at 400 Hz, the header says
    why, and the three modes are found."""
    sig = _shaker(period=8191, periods=6, seed=5)
    an = analyse_signals(sig, input=INPUT)
    dec = an.settings["decimation"]
    assert an.signals.fs == FS and dec["factors"] == [] and "8191 samples" in dec["reason"]
    assert an.frf.settings["period_samples"] == 8191
    assert "not decimated (no factor up to 10 divides the input's period" in report_text(an).splitlines()[0]
    _assert_three_modes(an.modal.natural_frequencies)


def test_broadband_record_decimates_as_before_and_the_option_turns_it_off():
    """Random force (not periodic): the factor floor(fs / (2.5 fmax)) in stages of at most 10, the
    data those of an order-9 Chebyshev I forward-backward low-pass; ``decimation=False`` keeps the rate and says so."""
    u = band_limited_random(FS, 80_000, fmin=2.0, fmax=15.0, rms=1.0, seed=3)
    sig = simulate(MODEL, u, FS, noise=0.02, seed=4)
    assert not detect_period(sig[INPUT], FS, fmax=15.0).is_periodic
    an = analyse_signals(sig, input=INPUT, fmax=15.0)
    assert an.settings["decimation"]["factors"] == [10] and an.signals.fs == 40.0
    assert an.frf.estimator == "H1"
    sos = scipy.signal.cheby1(9, 0.05, 0.8 / 10, output="sos")  # odd order: unit gain at 0 Hz
    ref = scipy.signal.sosfiltfilt(sos, sig.select(an.signals.channels).data, axis=-1)[:, ::10]
    np.testing.assert_array_equal(an.signals.data, ref)
    assert "decimated 400 → 40 Hz (factor 10: fs ≥ 2.5 × the 15 Hz band)" in report_text(an).splitlines()[0]
    _assert_three_modes(an.modal.natural_frequencies, rtol=1e-2)
    off = analyse_signals(sig, input=INPUT, fmax=15.0, decimation=False)
    assert off.signals.fs == FS and off.settings["decimation"] == {"fs_in": FS, "fs_out": FS, "factors": [],
                                                                  "reason": "decimation turned off"}
    assert "not decimated (decimation turned off)" in report_text(off).splitlines()[0]
    # no decimation needed (fmax near fs / 2.5): nothing said
    near = analyse_signals(sig, input=INPUT, fmax=150.0)
    assert near.signals.fs == FS and near.settings["decimation"]["reason"] is None
    assert "decimated" not in report_text(near).splitlines()[0]


def test_decimate_keeps_a_periodic_record_periodic(shaker):
    """``decimate(period=)``: the decimated input repeats every ``period / factor`` samples (away from
    the filter's edges), which the old factor 10 could not give."""
    dec = decimate(shaker, 15.0, period=PERIOD)
    assert dec.fs == 50.0 and dec.meta["decimated"]["factors"] == [8]
    x = dec[INPUT]
    p = detect_period(x, dec.fs)
    assert p.period_samples == 1024 and p.score > 0.999
    np.testing.assert_allclose(x[2048:3072], x[3072:4096], atol=1e-6 * np.abs(x).max())
    assert detect_period(decimate(shaker, 15.0)[INPUT], 40.0).score < 0.99  # 819.2 samples: not whole


def test_period_found_at_full_rate_through_out_of_band_noise():
    """``detect_period(fmax=)``: broadband noise as strong as the multisine hides the period at the full
    rate (score about 0.5); low-passed to the 15 Hz band it is found exactly."""
    one, _ = multisine(FS, 4096, fmin=2.0, fmax=15.0, seed=2)
    x = np.tile(one, 6) + np.random.default_rng(3).standard_normal(6 * 4096)
    assert not detect_period(x, FS).is_periodic
    p = detect_period(x, FS, fmax=15.0)
    assert p.is_periodic and p.period_samples == 4096
    with pytest.raises(ValueError, match="fmax"):
        detect_period(x, FS, fmax=0.0)


def test_cli_on_a_shaker_mcap(tmp_path, capsys, shaker):
    """``vibroscope analyse`` on a ROS 2 MCAP (WrenchStamped force, Imu accelerations) with no
    decimation option: the header line names the decimation, the JSON records it, the three modes
    within 0.5 %; ``--no-decimate`` analyses at 400 Hz."""
    from vibroscope.cli import main
    from vibroscope.io import write_ros2_mcap

    log = write_ros2_mcap(tmp_path / "shaker.mcap", shaker)
    js = tmp_path / "s.json"
    assert main(["analyse", str(log), "--input", INPUT, "--json", str(js), "--no-rrd", "--no-figures",
                 "--out", str(tmp_path)]) == 0
    header = capsys.readouterr().out.splitlines()[0]
    assert "at 50 Hz" in header and "decimated 400 → 50 Hz (factor 8" in header, header
    doc = json.loads(js.read_text())
    assert doc["settings"]["decimation"]["factors"] == [8] and doc["fs"] == 50.0
    _assert_three_modes([m["frequency_hz"] for m in doc["modes"]])
    assert main(["analyse", str(log), "--input", INPUT, "--json", str(js), "--no-rrd", "--no-figures",
                 "--out", str(tmp_path), "--no-decimate"]) == 0
    header = capsys.readouterr().out.splitlines()[0]
    assert "at 400 Hz" in header and "not decimated (decimation turned off)" in header, header
    doc = json.loads(js.read_text())
    assert doc["fs"] == FS and doc["settings"]["decimation"]["factors"] == []
    _assert_three_modes([m["frequency_hz"] for m in doc["modes"]])


def test_decimation_keeps_a_mean_such_as_gravity():
    """A constant 9.80665 m/s^2 plus a band-limited vibration: the decimated mean is the mean
    (scipy.signal.decimate's even-order filter passes it 1.1 % low)."""
    from vibroscope.pipeline import decimate
    from vibroscope.signals import Signals

    x = 9.80665 + 0.1 * band_limited_random(FS, 40_000, fmin=2.0, fmax=10.0, rms=1.0, seed=5)
    out = decimate(Signals(data=x[None, :], fs=FS, channels=("/imu.linear_acceleration.z",), units=("m/s^2",)), 10.0)
    assert out.fs == 40.0
    y = out.data[0, 200:-200]
    assert np.mean(y) == pytest.approx(np.mean(x[2000:-2000]), rel=2e-4)
    old = scipy.signal.decimate(x, 10, zero_phase=True)[200:-200]
    assert np.mean(old) < 0.995 * np.mean(y)  # the defect this replaces
