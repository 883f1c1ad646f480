"""Figures and rerun recording of a sim-to-real gap diagnosis, on a small synthetic GapReport."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from vibroscope.gap.report import (  # noqa: E402
    Band,
    Candidate,
    ChannelGap,
    GapReport,
    GapSpectrum,
    GapTraces,
    RegimeGap,
    SignatureTest,
)
from vibroscope.viewers import gap_figures  # noqa: E402
from vibroscope.viewers.gap_figures import (  # noqa: E402
    candidate_label,
    held_out_spans,
    plot_gap_report,
    verdict_index,
    where_label,
    zoom_window,
)

FS = 200.0
N = 2000
CHANNELS = ("/sim/m1.position.x", "/sim/m2.position.x")
UNITS = ("m", "m")
BANDS = (Band(8.0, 14.0, 0.62), Band(30.0, 40.0, 0.21))
PEAK = 1500  # where the nominal model is furthest off, inside the second held-out span


def make_report(**changes) -> GapReport:
    """2 outputs x 2000 samples, 2 bands, 3 candidates, 3 signature tests (2 with evidence)."""
    rng = np.random.default_rng(1)
    t = np.arange(N) / FS
    u = np.sin(2 * np.pi * 1.3 * t) + 0.5 * np.sin(2 * np.pi * 11.0 * t)
    nominal = np.vstack([1e-3 * np.sin(2 * np.pi * 1.3 * t - 0.3), 0.6e-3 * np.sin(2 * np.pi * 1.3 * t - 0.8)])
    distortion = 2e-4 * np.sign(np.cos(2 * np.pi * 1.3 * t)) * np.array([[1.0], [0.5]])
    bump = 1.5e-3 * np.exp(-0.5 * ((np.arange(N) - PEAK) / 8.0) ** 2) * np.array([[1.0], [0.7]])
    measured = nominal + distortion + bump + 2e-5 * rng.standard_normal((2, N))
    refit = nominal + 0.4 * (distortion + bump)
    augmented = nominal + 0.9 * (distortion + bump)
    validation = np.zeros(N, bool)
    validation[600:900] = True
    validation[1400:2000] = True
    traces = GapTraces(fs=FS, t0=12.5, channels=CHANNELS, units=UNITS, measured=measured, nominal=nominal,
                       refit=refit, augmented=augmented, validation=validation, input=u,
                       log="bench_run_3.mcap")

    f = np.linspace(0.0, FS / 2, 129)
    base = 1e-8 / (1 + (f / 5.0) ** 2)
    band_shape = 1 + 20 * np.exp(-0.5 * ((f - 11) / 2) ** 2) + 8 * np.exp(-0.5 * ((f - 35) / 3) ** 2)
    psd_meas = np.vstack([base, 0.5 * base]) * 10
    psd_meas[:, 0] = 0.0  # a zero bin, left out of the log plot
    r_before = np.vstack([base, 0.5 * base]) * band_shape
    noise = np.full((2, f.size), 1e-13)
    ff = np.linspace(0.5, 60.0, 97)
    w = 2 * np.pi * ff

    def h(wn, z, g):
        return g / (wn ** 2 - w ** 2 + 2j * z * wn * w)

    Hn = np.stack([h(2 * np.pi * 12, 0.05, 1.0), h(2 * np.pi * 12, 0.05, 0.6)], axis=1)
    Ha = np.stack([h(2 * np.pi * 11.5, 0.07, 1.0), h(2 * np.pi * 11.5, 0.07, 0.6)], axis=1)
    Hm = Ha * (1 + 0.03 * rng.standard_normal((ff.size, 2)))
    coh = np.clip(0.97 - 0.3 * np.exp(-0.5 * ((ff[:, None] - 11.5) / 2) ** 2), 0, 1) * np.ones((1, 2))
    spectrum = GapSpectrum(frequencies=f, measured=psd_meas, residual_before=r_before,
                           residual_refit=0.5 * r_before, residual_after=0.05 * r_before, noise=noise,
                           frf_frequencies=ff, frf_measured=Hm, frf_nominal=Hn, frf_augmented=Ha,
                           coherence=coh)

    v = np.linspace(-0.02, 0.02, 21)
    lags = np.arange(1, 51) / FS
    signatures = (
        SignatureTest(name="residual_vs_velocity", value=0.62, threshold=0.1, flagged=True,
                      points_to=("coulomb_friction", "hysteresis"),
                      detail="residual correlates with sign(v) across m1-ground: r = +0.62", x=v,
                      y=2e-4 * np.tanh(v / 0.002), x_label="relative velocity m1-ground [m/s]",
                      y_label="residual /sim/m1.position.x [m]"),
        SignatureTest(name="residual_whiteness", value=0.08, threshold=0.2, flagged=False, points_to=(),
                      detail="8 % of residual autocorrelation lags 1-50 outside the 99 % band",
                      x=lags, y=0.9 ** np.arange(1, 51), x_label="lag [s]", y_label="residual autocorrelation [-]"),
        SignatureTest(name="phase_slope", value=1e-5, threshold=2e-4, flagged=False, points_to=("time_delay",),
                      detail="no delay"),  # no evidence curve
    )
    candidates = (
        Candidate(effect="coulomb_friction", where={"between": ["m1", "ground"]}, parameters={"Fc_N": 0.8},
                  gap_after=0.081, score=0.71, gap_fit=0.079, n_parameters=1),
        Candidate(effect="hysteresis", where={"between": ["m1", "m2"]}, parameters={"alpha_N_per_m": 120.0},
                  gap_after=0.152, score=0.42, gap_fit=0.14, n_parameters=3),
        Candidate(effect="extra_mode", where={"dof": "m2", "frequency_hz": 33.0},
                  parameters={"frequency_hz": 33.0}, gap_after=0.224, score=0.18, gap_fit=0.2, n_parameters=2),
    )
    report = GapReport(
        metric="nrmse", validation="held-out time split (last 30 %)", noise_floor=0.02,
        noise_floor_method="residual PSD above the excited band", gap_before=0.31, gap_refit=0.27,
        gap_after=0.081, shrink=1 - 0.081 / 0.31, bands=BANDS,
        channels=(ChannelGap(channel=CHANNELS[0], gap=0.33, gap_after=0.08),
                  ChannelGap(channel=CHANNELS[1], gap=0.27, gap_after=0.09)),
        regimes=(RegimeGap("regime", "near_zero_velocity", 0.5, 0.2),),
        candidates=candidates, signatures=signatures, verdict="coulomb_friction", model_name="two_mass",
        traces=traces, spectrum=spectrum, timings={"total": 1.2}, meta={"fs_hz": FS})
    return dataclasses.replace(report, **changes) if changes else report


@pytest.fixture(scope="module")
def report():
    return make_report()


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _labels(ax):
    return [ln.get_label() for ln in ax.get_lines() if not ln.get_label().startswith("_")]


def test_importing_the_gap_viewers_loads_neither_rerun_nor_matplotlib():
    code = ("import sys, vibroscope.viewers, vibroscope.viewers.gap_figures, vibroscope.viewers.rerun_gap; "
            "bad = [m for m in ('rerun', 'matplotlib', 'rerun_bindings') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_lazy_registry_names_the_gap_viewers():
    import vibroscope.viewers as v

    assert v.plot_gap_report is plot_gap_report
    assert "log_gap_report" in v.__all__ and "plot_gap_report" in dir(v)


def test_every_figure_written_as_png(tmp_path, report):
    figs = plot_gap_report(report, out_dir=tmp_path / "figs")
    # every figure but the levels' one, which needs the BLA of several excitation levels
    assert list(figs) == [n for n in gap_figures.FIGURES if n != "gap_levels"]
    assert not (tmp_path / "figs" / "gap_levels.png").exists()
    for name in figs:
        p = tmp_path / "figs" / f"{name}.png"
        assert p.is_file(), name
        assert 10_000 < p.stat().st_size < 400_000, (name, p.stat().st_size)
        img = mpimg.imread(p)
        assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 600
        assert img[..., :3].std() > 0.05  # not blank
    assert report.plot().keys() == figs.keys()  # GapReport.plot uses the viewer
    assert not list(tmp_path.glob("*.png"))  # nothing written without out_dir


def test_time_figure(report):
    fig = gap_figures.plot_gap_time(report)
    tr = report.traces
    assert len(fig.axes) == 2 * len(CHANNELS)  # whole record + zoom per channel
    t = np.arange(N) / FS
    z0, z1, peak = zoom_window(tr)
    assert abs(peak - PEAK) <= 3 and z1 - z0 == 150 and z0 <= peak < z1  # 0.75 s around the bump
    for c in range(len(CHANNELS)):
        axf, axz = fig.axes[2 * c], fig.axes[2 * c + 1]
        assert _labels(axf) == ["measured", "nominal", "augmented (coulomb_friction)"]
        for ln, y in zip(axf.get_lines(), (tr.measured, tr.nominal, tr.augmented)):
            np.testing.assert_array_equal(ln.get_data()[0], t)
            np.testing.assert_array_equal(ln.get_data()[1], y[c])
        np.testing.assert_array_equal(axz.get_lines()[0].get_data()[1], tr.measured[c, z0:z1])
        assert axz.get_xlim() == pytest.approx((t[z0], t[z1 - 1]))
        shaded = [p for p in axf.patches if isinstance(p, Rectangle) and p.get_facecolor()[3] > 0]
        spans = [v for p in shaded for v in (p.get_x(), p.get_x() + p.get_width())]
        assert spans == pytest.approx([3.0, 4.5, 7.0, 10.0])  # samples 600-899 and 1400-1999
        assert CHANNELS[c] in axf.get_title(loc="left") and "[m]" in axf.get_ylabel()
        assert "0.330" in fig.axes[0].get_title(loc="left") and "0.080" in fig.axes[0].get_title(loc="left")
    assert "[s]" in fig.axes[-2].get_xlabel() and f"{peak / FS:.3f} s" in fig.axes[1].get_title()
    assert "held-out (validation)" in [t.get_text() for t in fig.legends[0].get_texts()]


def test_long_records_drawn_as_envelopes(report):
    tr = report.traces
    rep = 5  # 10 000 samples: above max_points
    long = dataclasses.replace(tr, measured=np.tile(tr.measured, rep), nominal=np.tile(tr.nominal, rep),
                               refit=np.tile(tr.refit, rep), augmented=np.tile(tr.augmented, rep),
                               validation=np.tile(tr.validation, rep), input=np.tile(tr.input, rep))
    fig = gap_figures.plot_gap_time(make_report(traces=long), max_points=4000)
    axf, axz = fig.axes[0], fig.axes[1]
    assert len(axf.collections) == 1  # the measured min-max band
    lines = axf.get_lines()
    assert len(lines) == 4  # nominal and augmented: upper and lower envelopes, 300 bins
    assert all(ln.get_xdata().size == 300 for ln in lines)
    np.testing.assert_allclose(lines[0].get_ydata().max(), tr.nominal[0].max())
    np.testing.assert_allclose(lines[1].get_ydata().min(), tr.nominal[0].min())
    assert len(axz.get_lines()) == 3 and axz.get_lines()[0].get_xdata().size == 150  # the zoom keeps the samples
    assert "min–max per" in axf.get_title(loc="left")


def test_frf_figure(report):
    fig = gap_figures.plot_gap_frf(report)
    sp = report.spectrum
    assert len(fig.axes) == 3 * len(CHANNELS)  # magnitude, phase, coherence per output
    axes = np.array(fig.axes).reshape(3, len(CHANNELS))
    for o in range(len(CHANNELS)):
        axm, axp, axc = axes[:, o]
        assert len(axm.get_lines()) == 3 and len(axp.get_lines()) == 3 and len(axc.get_lines()) == 1
        for ln, H in zip(axm.get_lines(), (sp.frf_measured, sp.frf_nominal, sp.frf_augmented)):
            np.testing.assert_allclose(ln.get_data()[1], 20 * np.log10(np.abs(H[:, o])))
        np.testing.assert_allclose(axp.get_lines()[2].get_data()[1], np.degrees(np.angle(sp.frf_augmented[:, o])))
        np.testing.assert_array_equal(axc.get_lines()[0].get_data()[1], sp.coherence[:, o])
        assert "dB" in axm.get_ylabel() and "m/N" in axm.get_ylabel() and "deg" in axp.get_ylabel()
        assert "Hz" in axc.get_xlabel() and axm.get_shared_x_axes().joined(axm, axc)
    assert _labels(axes[0, 0]) == ["measured H1", "nominal model", "augmented (coulomb_friction)"]


def test_spectrum_figure_shades_each_band(report):
    fig = gap_figures.plot_gap_spectrum(report)
    sp = report.spectrum
    assert len(fig.axes) == len(CHANNELS)
    for c, ax in enumerate(fig.axes):
        assert ax.get_yscale() == "log"
        lines = ax.get_lines()
        assert len(lines) == 5
        for ln, v in zip(lines, (sp.measured, sp.residual_before, sp.residual_refit, sp.residual_after, sp.noise)):
            y = np.asarray(v[c], dtype=float)
            np.testing.assert_array_equal(ln.get_data()[1], np.where(y > 0, y, np.nan))
        shades = [p for p in ax.patches if isinstance(p, Rectangle)]
        assert [(p.get_x(), p.get_x() + p.get_width()) for p in shades] == [(8.0, 14.0), (30.0, 40.0)]
        assert [t.get_text() for t in ax.texts] == ["62 %", "21 %"]
        assert "(m)^2/Hz" in ax.get_ylabel() or "m^2/Hz" in ax.get_ylabel()
    assert "noise floor" in _labels(fig.axes[0]) and "Hz" in fig.axes[-1].get_xlabel()


def test_spectrum_figure_y_range_is_the_shown_bands(report):
    """A measured PSD that falls to 1e-33 far above the located bands (EMPS: a position beyond
    its 0.5 Hz band) does not stretch the axis 20 decades below every curve in view."""
    sp = report.spectrum
    meas = np.array(sp.measured, dtype=float)
    meas[:, -1] = 1e-33  # the last line, at Nyquist, outside the shown band
    fig = gap_figures.plot_gap_spectrum(dataclasses.replace(report, spectrum=dataclasses.replace(sp, measured=meas)))
    lo, hi = gap_figures.focus_band(report, np.asarray(sp.frequencies))
    assert hi < float(np.asarray(sp.frequencies)[-1])
    for ax in fig.axes:
        assert ax.get_ylim()[0] > 1e-15  # the noise floor (1e-13) and the curves in view set it


def test_evidence_figure_one_panel_per_curve_flagged_highlighted(report):
    fig = gap_figures.plot_gap_evidence(report)
    axes = [a for a in fig.axes if a.get_visible()]
    assert len(axes) == 2  # phase_slope has no evidence curve
    vel, white = axes
    np.testing.assert_array_equal(vel.get_lines()[0].get_data()[0], report.signatures[0].x)
    np.testing.assert_array_equal(white.get_lines()[0].get_data()[1], report.signatures[1].y)
    assert vel.get_title().startswith("residual_vs_velocity: residual correlates")
    assert white.get_title().startswith("residual_whiteness")
    assert to_rgba(vel.get_lines()[0].get_color()) == to_rgba("C3")  # flagged: red, tinted panel
    assert to_rgba(white.get_lines()[0].get_color()) == to_rgba("C0")
    assert vel.get_facecolor() != white.get_facecolor()
    assert "coulomb_friction" in vel.get_legend().get_texts()[0].get_text()
    assert "m/s" in vel.get_xlabel() and "[m]" in vel.get_ylabel()


def test_candidates_figure_one_bar_each_verdict_highlighted(report):
    fig = gap_figures.plot_gap_candidates(report)
    ax = fig.axes[0]
    bars = [p for p in ax.patches if isinstance(p, Rectangle) and (p.get_gid() or "").startswith("candidate_")]
    assert len(bars) == len(report.candidates)
    np.testing.assert_allclose([b.get_width() for b in bars], [c.gap_after for c in report.candidates])
    colors = [b.get_facecolor() for b in bars]
    assert colors[0] == to_rgba(gap_figures.BAR_VERDICT) and colors[1] == colors[2] != colors[0]
    assert [t.get_text() for t in ax.get_yticklabels()] == [
        "coulomb_friction @ m1–ground", "hysteresis @ m1–m2", "extra_mode @ m2, 33 Hz"]
    vlines = {ln.get_label().rsplit(" ", 1)[0]: ln.get_xdata()[0] for ln in ax.get_lines()}
    assert vlines == {"nominal model": 0.31, "refitted linear model": 0.27, "noise floor": 0.02}
    assert "nrmse" in ax.get_xlabel() and "verdict coulomb_friction" in fig.get_suptitle()
    assert "(score +0.71)" in [t.get_text() for t in ax.texts][0]


def test_verdict_bar_follows_the_verdict_not_the_position(report):
    none = Candidate(effect="none", where={}, parameters={}, gap_after=0.31, score=0.0)
    r = make_report(candidates=(*report.candidates, none), verdict="none")
    assert verdict_index(r) == 3
    ax = gap_figures.plot_gap_candidates(r).axes[0]
    bars = [p for p in ax.patches if (p.get_gid() or "").startswith("candidate_")]
    assert [b.get_facecolor() == to_rgba(gap_figures.BAR_VERDICT) for b in bars] == [False, False, False, True]
    assert ax.get_yticklabels()[3].get_text() == "none"
    r2 = make_report(candidates=(dataclasses.replace(report.candidates[0], gap_after=float("inf")),
                                 *report.candidates[1:]))
    bars = [p for p in gap_figures.plot_gap_candidates(r2).axes[0].patches
            if (p.get_gid() or "").startswith("candidate_")]
    assert len(bars) == 3 and bars[0].get_hatch() == "//" and np.isfinite(bars[0].get_width())


def test_missing_parts_are_skipped(tmp_path):
    r = make_report(traces=None, spectrum=None)
    figs = plot_gap_report(r, out_dir=tmp_path)
    assert list(figs) == ["gap_evidence", "gap_candidates"]
    assert sorted(p.name for p in tmp_path.glob("*.png")) == ["gap_candidates.png", "gap_evidence.png"]
    empty = make_report(traces=None, spectrum=None, candidates=(), signatures=(), bands=(), channels=())
    assert plot_gap_report(empty) == {}
    # a spectrum without bands still draws, with nothing shaded
    nb = plot_gap_report(make_report(bands=()), names=["gap_spectrum"])
    assert list(nb) == ["gap_spectrum"] and not nb["gap_spectrum"].axes[0].patches
    with pytest.raises(ValueError, match="unknown gap figure"):
        plot_gap_report(r, names=["gap_nope"])


def test_helpers():
    assert where_label({"between": ["m1", "ground"]}) == "m1–ground"
    assert where_label({"dof": "m2", "frequency_hz": 12.345}) == "m2, 12.3 Hz"
    assert where_label({"side": "input"}) == "input"
    assert where_label({"parameters": ["k1", "c1"]}) == "k1, c1"
    assert where_label({}) == ""
    assert candidate_label(Candidate(effect="time_delay", where={"side": "input"}, parameters={},
                                     gap_after=0.1, score=0.1)) == "time_delay @ input"
    # an effect fitted in two forms names its form beside it, short enough for the bar labels
    joint = Candidate(effect="joint_friction",
                      where={"between": ["m1", "ground"], "form": "iwan", "character": "softening"},
                      parameters={}, gap_after=0.1, score=0.1)
    assert candidate_label(joint) == "joint_friction (iwan) @ m1–ground, softening"
    assert held_out_spans(np.array([0, 1, 1, 0, 1], bool)) == [(1, 3), (4, 5)]
    assert held_out_spans(np.zeros(0, bool)) == []


# ------------------------------------------------------------------------------------------------
# rerun
# ------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def rrd(report, tmp_path_factory):
    pytest.importorskip("rerun")
    from vibroscope.viewers.rerun_gap import log_gap_report

    path = tmp_path_factory.mktemp("gap_rrd") / "gap.rrd"
    assert log_gap_report(report, path=path, recording_id="gap-1") == path
    return path


@pytest.fixture(scope="module")
def data(rrd):
    from vibroscope.viewers.rerun_view import read_rrd

    return read_rrd(rrd)


def test_rrd_is_one_complete_recording_with_a_blueprint(rrd):
    import rerun as rr
    from rerun.chunk import RrdReader
    from rerun_bindings import check_for_rrd_footer

    assert check_for_rrd_footer(str(rrd))
    reader = RrdReader(rrd)
    recs = reader.recordings()
    assert len(recs) == 1 and recs[0].recording_id == "gap-1"
    assert len(reader.blueprints()) == 1
    assert rr.get_global_data_recording() is None


def test_rrd_time_series(report, data):
    from vibroscope.viewers.rerun_view import channel_entity

    tr = report.traces
    t_ns = np.round(np.arange(N) / FS * 1e9).astype(np.int64)
    for c, ch in enumerate(CHANNELS):
        for what in ("measured", "nominal", "refit", "augmented"):
            ent = data[channel_entity("signals", ch) + f"/{what}"]
            np.testing.assert_array_equal(ent["time"], t_ns)
            np.testing.assert_array_equal(ent["Scalars:scalars"], getattr(tr, what)[c])
            assert ent["static"]["SeriesLines:names"][0] == f"{what} [m]"
    assert channel_entity("signals", CHANNELS[0]) == "/signals/sim/m1.position.x"
    np.testing.assert_array_equal(data["/validation"]["Scalars:scalars"], tr.validation.astype(float))
    np.testing.assert_array_equal(data["/input"]["Scalars:scalars"], tr.input)


def test_rrd_spectra_and_frf(report, data):
    from vibroscope.viewers.rerun_view import channel_entity, frequency_index

    sp = report.spectrum
    name, idx = frequency_index(sp.frequencies)
    assert name == "frequency_mHz"
    for c, ch in enumerate(CHANNELS):
        for what in ("measured", "residual_before", "residual_refit", "residual_after", "noise"):
            ent = data[channel_entity("psd", ch) + f"/{what}"]
            np.testing.assert_array_equal(ent["frequency_mHz"], idx)
            v = getattr(sp, what)[c]
            with np.errstate(divide="ignore"):
                np.testing.assert_allclose(ent["Scalars:scalars"], np.where(v > 0, 10 * np.log10(v), np.nan))
        _, fidx = frequency_index(sp.frf_frequencies)
        mag = data[channel_entity("frf/magnitude_db", ch) + "/nominal"]
        np.testing.assert_array_equal(mag["frequency_mHz"], fidx)
        np.testing.assert_allclose(mag["Scalars:scalars"], 20 * np.log10(np.abs(sp.frf_nominal[:, c])))
        np.testing.assert_allclose(data[channel_entity("frf/phase_deg", ch) + "/measured"]["Scalars:scalars"],
                                   np.degrees(np.angle(sp.frf_measured[:, c])))
        np.testing.assert_array_equal(data[channel_entity("frf/coherence", ch)]["Scalars:scalars"],
                                      sp.coherence[:, c])
    bands = data["/psd/bands"]["static"]["TextDocument:text"][0]
    assert "| 1 | 8.000 | 14.000 | 62.0 |" in bands and "| 2 | 30.000 | 40.000 | 21.0 |" in bands


def _bar_values(col) -> np.ndarray:
    """The values of a logged BarChart (TensorData: shape, names, buffer union), as read by read_rrd."""
    v = col[0] if isinstance(col, list) else col
    buf = v["buffer"] if isinstance(v, dict) else v
    if isinstance(buf, tuple):  # (type tag, values) of the arrow union
        buf = buf[1]
    return np.asarray(buf, dtype=float)


def test_rrd_candidates_bar_chart_and_texts(report, data):
    gaps = [c.gap_after for c in report.candidates]
    np.testing.assert_array_equal(_bar_values(data["/candidates/gap_after"]["static"]["BarChart:values"]), gaps)
    np.testing.assert_array_equal(_bar_values(data["/candidates/verdict"]["static"]["BarChart:values"]),
                                  [gaps[0], 0.0, 0.0])
    np.testing.assert_array_equal(_bar_values(data["/gaps"]["static"]["BarChart:values"]), [0.31, 0.27, 0.081, 0.02])
    table = data["/candidates/table"]["static"]["TextDocument:text"][0]
    assert "| 0 | **coulomb_friction @ m1–ground** (verdict) | 0.0810 |" in table
    assert "| 2 | extra_mode @ m2, 33 Hz | 0.2240 |" in table
    assert data["/summary"]["static"]["TextDocument:text"][0] == report.summary()
    about = data["/about"]["static"]["TextDocument:text"][0]
    assert "frequency_mHz" in about and "t0 = 12.5 s" in about and "3.000–4.500 s" in about


def test_rrd_blueprint_tabs_and_views(rrd):
    from vibroscope.viewers.rerun_view import channel_entity, read_rrd

    bp = read_rrd(rrd, blueprint=True)
    views, containers = {}, []
    for ent, cols in bp.items():
        if "ViewBlueprint:class_identifier" in cols:
            views[cols["ViewBlueprint:space_origin"][-1]] = cols["ViewBlueprint:class_identifier"][-1]
        if "ContainerBlueprint:container_kind" in cols:
            containers.append(cols.get("ContainerBlueprint:display_name", [None])[-1])
    for ch in CHANNELS:
        assert views[channel_entity("signals", ch)] == "TimeSeries"
        assert views[channel_entity("psd", ch)] == "TimeSeries"
    for origin in ("/input", "/validation", "/frf/magnitude_db", "/frf/phase_deg", "/frf/coherence"):
        assert views[origin] == "TimeSeries"
    assert views["/candidates"] == "BarChart" and views["/gaps"] == "BarChart"
    for origin in ("/summary", "/about", "/candidates/table", "/psd/bands"):
        assert views[origin] == "TextDocument"
    assert {"Time: measured / nominal / augmented (timeline: time)", "Gap spectrum (timeline: frequency_mHz)",
            "FRF (timeline: frequency_mHz)", "Candidates", "Summary"} <= set(containers)
    assert bp["/time_panel"]["TimePanelBlueprint:timeline"][-1] == "time"


def test_rrd_without_traces_or_spectrum(tmp_path):
    pytest.importorskip("rerun")
    from vibroscope.viewers.rerun_gap import log_gap_report
    from vibroscope.viewers.rerun_view import read_rrd

    r = make_report(traces=None, spectrum=None)
    d = read_rrd(log_gap_report(r, path=tmp_path / "bare.rrd"))
    assert not any(k.startswith(("/signals", "/psd", "/frf")) for k in d)
    assert "/candidates/gap_after" in d and d["/summary"]["static"]["TextDocument:text"][0] == r.summary()
    bp = read_rrd(tmp_path / "bare.rrd", blueprint=True)
    origins = {c["ViewBlueprint:space_origin"][-1] for c in bp.values() if "ViewBlueprint:space_origin" in c}
    assert origins == {"/candidates", "/gaps", "/candidates/table", "/summary", "/about"}


def test_rrd_into_a_given_recording_and_needs_a_sink(tmp_path, report):
    rr = pytest.importorskip("rerun")
    from vibroscope.viewers.rerun_gap import log_gap_report
    from vibroscope.viewers.rerun_view import read_rrd

    with pytest.raises(ValueError, match="path, spawn"):
        log_gap_report(report)
    rec = rr.RecordingStream("mine", recording_id="outer")
    rec.save(str(tmp_path / "outer.rrd"))
    rec.log("before", rr.TextDocument("logged by the caller"), static=True)
    assert log_gap_report(report, recording=rec) is None
    rec.log("after", rr.TextDocument("still open"), static=True)
    rec.disconnect()
    d = read_rrd(tmp_path / "outer.rrd")
    assert {"/before", "/after", "/summary", "/candidates/gap_after"} <= set(d)
    assert "/__properties" not in d or "RecordingInfo:name" not in d["/__properties"].get("static", {})


@pytest.mark.parametrize("qualname", [
    "gap_figures.plot_gap_report", "gap_figures.plot_gap_time", "gap_figures.plot_gap_frf",
    "gap_figures.plot_gap_spectrum", "gap_figures.plot_gap_evidence", "gap_figures.plot_gap_candidates",
    "rerun_gap.log_gap_report",
])
def test_public_gap_viewer_functions_document_every_parameter(qualname):
    import importlib
    import inspect
    import re

    mod, name = qualname.split(".")
    fn = getattr(importlib.import_module(f"vibroscope.viewers.{mod}"), name)
    doc = inspect.getdoc(fn) or ""
    assert "Returns" in doc
    for p in inspect.signature(fn).parameters.values():
        assert re.search(rf"^\s*{p.name}\b|[ ,]{p.name}\b.*:", doc, re.M), f"{qualname}: {p.name!r} undocumented"
