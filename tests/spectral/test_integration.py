"""Integration to velocity and displacement, ISO 20816-1 severity and operating deflection shapes,
against analytic truth; the acquisition figures built on them."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.modal import mac
from vibroscope.models import demo_model
from vibroscope.signals import Signals
from vibroscope.spectral import FRF, csd_matrix
from vibroscope.spectral.integration import (
    OperatingShape,
    Severity,
    default_f_cut,
    highpass_gain,
    integrate,
    ods,
    velocity_and_displacement,
    vibration_severity,
)

FS = 1000.0
T = 60.0
F_CUT = 1.0
# amplitudes (m/s²), frequencies (Hz, all >= 3 f_cut) and phases of the sum of sines
AMP = np.array([2.0, 1.0, 0.5])
FREQ = np.array([3.3, 8.1, 21.7])
PHASE = np.array([0.3, 1.1, 2.0])


def _rel_rms(y, ref):
    return float(np.sqrt(np.mean((y - ref) ** 2)) / np.sqrt(np.mean(ref ** 2)))


@pytest.fixture(scope="module")
def sines():
    """a(t) = Σ A_i sin(ω_i t + φ_i) + 1.5 m/s² offset + 0.02 m/s³ ramp + 0.3 sin(2π 0.05 t) wander,
    with the analytic zero-mean velocity and displacement of the sines."""
    t = np.arange(int(FS * T)) / FS
    w = 2 * np.pi * FREQ
    arg = w[:, None] * t + PHASE[:, None]
    a = (AMP[:, None] * np.sin(arg)).sum(0) + 1.5 + 0.02 * t + 0.3 * np.sin(2 * np.pi * 0.05 * t)
    v = -(AMP[:, None] / w[:, None] * np.cos(arg)).sum(0)
    d = -(AMP[:, None] / w[:, None] ** 2 * np.sin(arg)).sum(0)
    sig = Signals(data=np.vstack([a, -2.0 * a]), fs=FS, channels=["/imu/m1.linear_acceleration.x",
                                                                  "/imu/m2.linear_acceleration.x"],
                  units=["m/s^2", "m/s²"])
    return sig, v, d


@pytest.mark.parametrize("method", ["frequency", "highpass"])
@pytest.mark.parametrize("order", [1, 2])
def test_integrate_recovers_analytic_velocity_and_displacement(sines, method, order):
    """Within 1 % RMS over the interior (first and last 5 % left out), both channels, despite
    the offset, the ramp and the slow wander, for components at >= 3 f_cut."""
    sig, v, d = sines
    out = integrate(sig, order=order, f_cut=F_CUT, method=method)
    truth = v if order == 1 else d
    k = int(0.05 * sig.n_samples)
    inner = slice(k, sig.n_samples - k)
    for row, gain in ((0, 1.0), (1, -2.0)):
        err = _rel_rms(out.data[row, inner], gain * truth[inner])
        assert err < 0.01, f"{method=} {order=} channel {row}: {err=:.2e}"


@pytest.mark.parametrize("method", ["frequency", "highpass"])
def test_velocity_and_displacement_in_one_pass_equal_two_integrations(sines, method):
    """One pass gives integrate(order=1) and integrate(order=2) bit for bit (data, units, meta),
    with a gap too; the displacement is the analytic one away from the ends."""
    sig, _v, d = sines
    gappy = sig.data.copy()
    gappy[1, 20_000:20_100] = np.nan
    for s in (sig, Signals(data=gappy, fs=FS, channels=sig.channels, units=sig.units)):
        vel, disp = velocity_and_displacement(s, f_cut=F_CUT, method=method)
        for got, order in ((vel, 1), (disp, 2)):
            ref = integrate(s, order=order, f_cut=F_CUT, method=method)
            np.testing.assert_array_equal(got.data, ref.data)
            assert got.units == ref.units and got.meta == ref.meta
    keep = slice(int(3 * FS / F_CUT), -int(3 * FS / F_CUT))
    assert _rel_rms(disp.data[0, keep], d[keep]) < 0.01


def test_frequency_method_is_accurate_to_within_one_over_f_cut_of_the_ends(sines):
    """The antisymmetric extension leaves edge zones of about 1/f_cut: beyond 2 s (3 % of 60 s),
    better than 0.5 %; over the whole record, displacement still within 5 %."""
    sig, v, d = sines
    vel = integrate(sig.select([0]), order=1, f_cut=F_CUT)
    dis = integrate(sig.select([0]), order=2, f_cut=F_CUT)
    k = int(2.0 * FS)
    assert _rel_rms(vel.data[0, k:-k], v[k:-k]) < 0.005
    assert _rel_rms(dis.data[0, k:-k], d[k:-k]) < 0.005
    assert _rel_rms(dis.data[0], d) < 0.05


@pytest.mark.parametrize("method", ["frequency", "highpass"])
def test_integrate_applies_the_documented_highpass(method):
    """A tone at f_cut comes out with W(f_cut) = 1/2 of its velocity amplitude A/ω."""
    fs, f0 = 200.0, 2.0
    t = np.arange(int(fs * 100)) / fs
    sig = Signals(data=np.sin(2 * np.pi * f0 * t), fs=fs, channels=["a"], units=["m/s^2"])
    vel = integrate(sig, f_cut=f0, method=method)
    assert highpass_gain(f0, f0) == pytest.approx(0.5)
    k = int(0.2 * t.size)
    amp = np.sqrt(2) * np.sqrt(np.mean(vel.data[0, k:-k] ** 2))
    assert amp == pytest.approx(0.5 / (2 * np.pi * f0), rel=0.01)


def test_integrate_units_names_and_meta(sines):
    sig, _, _ = sines
    vel = integrate(sig)
    dis = integrate(sig, order=2, method="highpass")
    assert vel.channels == sig.channels and vel.fs == sig.fs and vel.t0 == sig.t0
    assert vel.units == ("m/s", "m/s")
    assert dis.units == ("m", "m")
    assert vel.meta["integration"]["f_cut_hz"] == default_f_cut(FS, sig.n_samples) == 1.0
    assert {"order", "f_cut_hz", "method"} <= set(dis.meta["integration"])
    assert dis.meta["integration"]["order"] == 2 and dis.meta["integration"]["method"] == "highpass"
    other = Signals(data=np.zeros((3, 100)), fs=100.0, channels=["f", "x", "n"], units=["N", "", "m/s"])
    assert integrate(other).units == ("N·s", "", "m")
    assert integrate(other, order=2).units == ("N·s²", "", "m·s")
    assert default_f_cut(100.0, 100) == 10.0  # 1 s record: ten cycles


def test_integrate_rejects_bad_settings():
    sig = Signals(data=np.zeros(1000), fs=100.0, channels=["a"], units=["m/s^2"])
    with pytest.raises(ValueError, match="order"):
        integrate(sig, order=3)
    with pytest.raises(ValueError, match="method"):
        integrate(sig, method="trapezoid")
    with pytest.raises(ValueError, match="f_cut"):
        integrate(sig, f_cut=50.0)
    with pytest.raises(ValueError, match="f_cut"):
        integrate(sig, f_cut=0.0)


# -- severity ---------------------------------------------------------------------------------
@pytest.mark.parametrize("fs", [4000.0, 2500.0])
def test_severity_of_a_50_hz_tone_excludes_a_5_hz_one(fs):
    """ISO 20816-1: 10 m/s² at 50 Hz is 10/(2π·50·√2) m/s = 22.51 mm/s; 10 m/s² at 5 Hz (outside
    10–1000 Hz, 10× more velocity) adds nothing measurable."""
    t = np.arange(int(fs * 20)) / fs
    A = 10.0
    a50 = A * np.sin(2 * np.pi * 50.3 * t + 0.4)
    a5 = A * np.sin(2 * np.pi * 5.0 * t + 1.0)
    sig = Signals(data=np.vstack([a50, a50 + a5 + 0.7, a5]), fs=fs, channels=["tone", "tone+5Hz", "5Hz"],
                  units=["m/s^2"] * 3)
    sev = vibration_severity(sig)
    assert isinstance(sev, Severity)
    expect = A / (2 * np.pi * 50.3 * np.sqrt(2)) * 1000
    assert sev["tone"] == pytest.approx(expect, rel=0.005)
    assert sev["tone+5Hz"] == pytest.approx(expect, rel=0.005)
    assert sev["5Hz"] < 0.005 * A / (2 * np.pi * 5.0 * np.sqrt(2)) * 1000
    assert sev.band_hz == (10.0, 1000.0) and sev.note == ""
    assert not sev.velocity_rms_mm_s.flags.writeable


def test_severity_clips_the_band_at_nyquist_and_says_so():
    fs = 1000.0
    t = np.arange(int(fs * 20)) / fs
    sig = Signals(data=0.1 * np.sin(2 * np.pi * 100.0 * t), fs=fs, channels=["a"], units=["g"])
    sev = vibration_severity(sig)
    assert sev.band_hz == (10.0, 500.0)
    assert "Nyquist" in sev.note
    # 0.1 g at 100 Hz
    assert sev["a"] == pytest.approx(0.980665 / (2 * np.pi * 100 * np.sqrt(2)) * 1000, rel=0.005)
    with pytest.raises(ValueError, match="acceleration"):
        vibration_severity(Signals(data=np.zeros(1000), fs=fs, channels=["f"], units=["N"]))
    assert "taken as m/s^2" in vibration_severity(Signals(data=np.ones(4000), fs=fs, channels=["u"])).note


# -- operating deflection shapes ---------------------------------------------------------------
@pytest.fixture(scope="module")
def demo_frf():
    model = demo_model()
    f = np.arange(0.0, 120.0, 0.01)
    H = model.frf(f, "acceleration")
    h = FRF(frequencies=f, H=H, coherence=np.ones(H.shape[:2]), inputs=model.input_channels(),
            outputs=model.output_channels(), estimator="analytic", kind="accelerance", units="m/s^2/N")
    return model, h


def test_ods_from_frf_at_a_natural_frequency_is_the_mode_shape(demo_frf):
    """At the lightly damped, well separated modes 1 (18.4 Hz, ζ 1.0 %) and 2 (41.9 Hz, 2.3 %)
    the ODS is the mode shape (MAC > 0.99). At mode 3 (60.4 Hz, 3.0 %) the in-phase tails of
    modes 1 and 2 still add to it (MAC 0.90: an ODS, not a mode; Richardson 1997); its part in
    quadrature with the force is the mode shape (quadrature picking, MAC > 0.999)."""
    model, h = demo_frf
    modes = model.modes()
    out_dofs = [o.dof for o in model.outputs]
    cols = [list(modes.dofs).index(d) for d in out_dofs]
    for r, fn in enumerate(modes.natural_frequencies):
        o = ods(h, fn)
        assert isinstance(o, OperatingShape) and o.source == "frf"
        assert abs(o.frequency - fn) <= 0.005 + 1e-9
        m_ods = mac(o.shape, modes.shapes[r, cols])[0, 0]
        assert m_ods > 0.99 if r < 2 else 0.85 < m_ods < 0.95, (r, m_ods)
        assert mac(o.values.imag, modes.shapes[r, cols])[0, 0] > 0.999
        assert np.max(np.abs(o.shape)) == pytest.approx(1.0)
        ref = o.points.index(o.reference)
        assert o.shape[ref].imag == 0 and o.shape[ref].real > 0
        assert o.values == pytest.approx(h.H[round(o.frequency / 0.01), :, 0])
    # between the first two modes the ODS is a mix, not the first mode
    mid = ods(h, 0.5 * (modes.natural_frequencies[0] + modes.natural_frequencies[1]))
    assert mac(mid.shape, modes.shapes[0, cols])[0, 0] < 0.9


def test_ods_rejects_frequencies_off_the_axis(demo_frf):
    _, h = demo_frf
    with pytest.raises(ValueError, match="outside"):
        ods(h, 200.0)
    with pytest.raises(ValueError, match="outside"):
        ods(h, -1.0)
    with pytest.raises(KeyError):
        ods(h, 20.0, input="nope")
    with pytest.raises(TypeError):
        ods(np.zeros(3), 20.0)


def test_ods_from_csd_of_correlated_channels_has_their_gain_and_phase():
    """y = g·x delayed by D samples: at f, y/x = g·exp(−j 2π f D / fs). (The delay misaligns
    D of the 512 samples of each segment: a bias of about D/512 in the ratio.)"""
    fs, g, D = 512.0, 2.5, 2
    x = np.random.default_rng(0).standard_normal(2 ** 16)
    y = g * np.roll(x, D)
    G = csd_matrix(Signals(data=np.vstack([x, y]), fs=fs, channels=["x", "y"], units=["m/s^2", "m/s^2"]), nperseg=512)
    f0 = 40.0
    expect = g * np.exp(-2j * np.pi * f0 * D / fs)
    o = ods(G, f0)  # default reference: the larger auto-spectrum, y
    assert o.source == "csd" and o.reference == "y" and o.frequency == f0
    assert o.shape[1] == pytest.approx(1.0)
    ratio = o.shape[1] / o.shape[0]
    assert abs(ratio) == pytest.approx(g, rel=0.005)
    assert np.degrees(np.angle(ratio / expect)) == pytest.approx(0.0, abs=0.2)
    o_x = ods(G, f0, reference="x")
    assert o_x.reference == "x" and o_x.shape[0].imag == 0 and o_x.shape[0].real > 0
    assert o_x.shape[1] / o_x.shape[0] == pytest.approx(expect, rel=0.005)
    assert np.abs(o_x.values[0]) ** 2 == pytest.approx(np.real(G.G[round(f0), 0, 0]))
    assert o_x.units == "m/s^2/√Hz"


# -- figures ------------------------------------------------------------------------------------
def test_plot_kinematics_has_three_rows_per_channel(sines, tmp_path, check_png):
    from vibroscope.viewers.acquisition import plot_kinematics

    sig, _, _ = sines
    fig = plot_kinematics(sig.select([0]).with_meta(), f_cut=F_CUT)
    assert len(fig.axes) == 3
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == ["acceleration [m/s²]", "velocity [mm/s]", "displacement [mm]"]
    assert "f_cut = 1 Hz" in fig._suptitle.get_text()
    fig2 = plot_kinematics(sig, max_channels=5, method="highpass")
    assert len(fig2.axes) == 6
    for f, name in ((fig, "k1.png"), (fig2, "k2.png")):
        f.savefig(tmp_path / name)
        check_png(tmp_path / name)


def test_plot_ods_draws_it_like_a_mode(demo_frf, tmp_path, check_png):
    from vibroscope.modal import ods_as_modal_model

    model, h = demo_frf
    fn = model.modes().natural_frequencies[1]
    o = ods(h, fn)
    m = ods_as_modal_model(o)
    assert m.method == "ods" and len(m) == 1 and np.isnan(m.damping_ratios[0])
    assert m.shapes[0] == pytest.approx(o.shape) and m.points == o.points
    fig = o.plot()
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 1
    assert visible[0].get_title().startswith(f"ODS at {o.frequency:.4g} Hz")
    assert "Operating deflection shape" in fig._suptitle.get_text()
    fig.savefig(tmp_path / "ods.png")
    check_png(tmp_path / "ods.png")


def test_log_ods_writes_an_animated_recording(demo_frf, tmp_path):
    pytest.importorskip("rerun")
    from vibroscope.viewers.acquisition import log_ods

    model, h = demo_frf
    path = log_ods(ods(h, model.modes().natural_frequencies[0]), rrd_path=tmp_path / "ods.rrd")
    assert path.exists() and path.stat().st_size > 1000


@pytest.mark.parametrize("method", ["frequency", "highpass"])
def test_integrate_does_not_bridge_gaps(sines, method):
    """A record with gaps (NaN: a lost chunk) integrates stretch by stretch: the missing samples and
    a stretch under 4 samples stay NaN, each stretch equals the integral of that stretch alone, and
    away from the stretches' edge zones (3 / f_cut) the velocity is the analytic one (before: scipy's
    "array must not contain infs or NaNs", and `vibroscope analyse` of such a log failed)."""
    sig, v, _d = sines
    x = np.array(sig.data)
    x[:, 25_000:25_300] = np.nan  # a lost chunk
    x[1, 40_000:40_002] = np.nan  # one row only, leaving a 3-sample stretch after it
    x[1, 40_005:40_006] = np.nan
    out = integrate(Signals(data=x, fs=FS, channels=sig.channels, units=sig.units), order=1, f_cut=F_CUT, method=method)
    assert np.array_equal(np.isnan(out.data), np.isnan(x) | (np.arange(x.shape[1]) >= 40_002)
                          & (np.arange(x.shape[1]) < 40_005) & (np.arange(2) == 1)[:, None])
    for row, (a, b) in ((0, (25_300, x.shape[1])), (1, (25_300, 40_000))):
        alone = integrate(Signals(data=x[row : row + 1, a:b], fs=FS, channels=sig.channels[:1], units=sig.units[:1]),
                          order=1,
                          f_cut=F_CUT, method=method)
        assert np.array_equal(out.data[row, a:b], alone.data[0])
    k = int(3 * FS / F_CUT)
    for a, b in ((0, 25_000), (25_300, 40_000)):
        inner = slice(a + k, b - k)
        assert _rel_rms(out.data[0, inner], v[inner]) < 0.01
    assert "stretches between missing samples" in out.meta["integration"]["gaps"]
    assert "gaps" not in integrate(sig, order=1, f_cut=F_CUT).meta["integration"]


@pytest.mark.parametrize("n", [4, 5, 64, 1001, 30000])
def test_frequency_integration_is_the_fft_of_the_antisymmetric_extension(n):
    """The length-n DST-II / DCT-III pair gives what its definition gives: the FFT of the row
    extended to ``[x, -x reversed]`` (length 2n), times ``W(f) / (j 2π f)`` with the Nyquist bin
    zero, inverted and cut to the first n samples; for even and odd n."""
    import scipy.fft

    from vibroscope.spectral.integration import _integrate_frequency

    rng = np.random.default_rng(n)
    x = rng.standard_normal((2, n)) + np.linspace(0.0, 3.0, n)
    fs, f_cut = 500.0, 500.0 * 3.0 / n + 1e-3
    xe = np.concatenate([x, -x[:, ::-1]], axis=-1)
    f = scipy.fft.rfftfreq(2 * n, 1.0 / fs)
    H = np.zeros(f.shape, dtype=complex)
    H[1:] = highpass_gain(f[1:], f_cut) / (2j * np.pi * f[1:])
    H[-1] = 0.0
    ref = scipy.fft.irfft(scipy.fft.rfft(xe, axis=-1) * H, 2 * n, axis=-1)[:, :n]
    got = _integrate_frequency(x, fs, f_cut)
    assert got.shape == x.shape
    assert np.max(np.abs(got - ref)) <= 1e-12 * np.sqrt(np.mean(ref ** 2))
