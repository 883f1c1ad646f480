"""Matplotlib figures of the viewers: the PNGs exist, are readable-sized, and draw the data."""

from __future__ import annotations

import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import _viewers_synthetic as syn  # noqa: E402
from vibroscope.viewers import figures  # noqa: E402
from vibroscope.viewers._common import real_shape, sensor_geometry  # noqa: E402


@pytest.fixture(scope="module")
def results():
    psd, csd, frf, sv = syn.spectra()
    return {"signals": syn.signals(), "psd": psd, "csd": csd, "frf": frf, "sv": sv, "modal": syn.modal()}


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def test_importing_viewers_loads_neither_rerun_nor_matplotlib():
    code = ("import sys, vibroscope.viewers, vibroscope.viewers.figures, vibroscope.viewers.rerun_view; "
            "bad = [m for m in ('rerun', 'matplotlib', 'rerun_bindings') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_summary_figures_writes_every_png(tmp_path, results):
    paths = figures.summary_figures(tmp_path / "figs", signals=results["signals"], psd=results["psd"],
                                    frf=results["frf"], modal=results["modal"], sv=results["sv"],
                                    coords=syn.coords(), true_modes=results["modal"])
    names = [p.name for p in paths]
    assert names == ["signals.png", "psd.png", "frf.png", "modes.png", "singular_values.png"]
    from PIL import Image

    for p in paths:
        assert p.is_file()
        size = p.stat().st_size
        assert 10_000 < size < 300_000, (p.name, size)
        img = mpimg.imread(p)
        assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 600
        assert img[..., :3].std() > 0.05  # not blank
        with Image.open(p) as im:  # palette-quantised, as written by figures.save_figure
            assert im.format == "PNG" and im.mode == "P" and len(im.getcolors(256)) > 8
    # the PNG is the figure at figures.DPI, pixel for pixel
    fig = figures.plot_mode_shapes(results["modal"], syn.coords(), true_modes=results["modal"])
    w, h = np.round(fig.get_size_inches() * figures.DPI).astype(int)
    with Image.open(tmp_path / "figs" / "modes.png") as im:
        assert im.size == (w, h)


def test_summary_figures_only_what_is_given(tmp_path, results):
    paths = figures.summary_figures(tmp_path, modal=results["modal"])
    assert [p.name for p in paths] == ["modes.png"]
    assert figures.summary_figures(tmp_path / "none") == []


def test_plot_spectrum_draws_the_values(results):
    psd = results["psd"]
    ax = figures.plot_spectrum(psd, channels=[psd.channels[2], 0])
    lines = ax.get_lines()
    assert len(lines) == 2
    x, y = lines[0].get_data()
    pos = psd.values[2] > 0
    np.testing.assert_array_equal(x, psd.frequencies[pos])
    np.testing.assert_array_equal(y, psd.values[2][pos])
    assert ax.get_yscale() == "log"
    assert "Hz" in ax.get_xlabel() and "(m/s^2)^2/Hz" in ax.get_ylabel()
    assert ax.get_legend() is not None

    ax = figures.plot_spectrum(psd, db=True)
    np.testing.assert_allclose(ax.get_lines()[1].get_data()[1][1:], 10 * np.log10(psd.values[1][1:]))
    assert "dB" in ax.get_ylabel()


def test_spectrum_plot_method_uses_the_viewer(results):
    ax = results["psd"].plot()
    assert len(ax.get_lines()) == len(results["psd"].channels)


def test_plot_frf_three_axes_sharing_frequency(results):
    frf = results["frf"]
    fig = figures.plot_frf(frf, output=frf.outputs[1])
    axm, axp, axc = fig.axes
    f, mag = axm.get_lines()[0].get_data()
    np.testing.assert_array_equal(f, frf.frequencies)
    with np.errstate(divide="ignore"):
        np.testing.assert_allclose(mag, 20 * np.log10(np.abs(frf.H[:, 1, 0])))
    np.testing.assert_allclose(axp.get_lines()[0].get_data()[1], np.degrees(np.angle(frf.H[:, 1, 0])))
    np.testing.assert_array_equal(axc.get_lines()[0].get_data()[1], frf.coherence[:, 1])
    assert axm.get_shared_x_axes().joined(axm, axc)
    assert "dB" in axm.get_ylabel() and "m/s^2/N" in axm.get_ylabel()
    assert "deg" in axp.get_ylabel() and "Hz" in axc.get_xlabel()
    assert frf.plot().axes  # the result's own plot method


def test_plot_mode_shapes_against_height(results):
    modal = results["modal"]
    fig = figures.plot_mode_shapes(modal, syn.coords())
    axes = [a for a in fig.axes if a.get_visible()]
    assert len(axes) == len(modal.natural_frequencies)
    pos, _, _ = sensor_geometry(modal.points, syn.coords())
    for r, ax in enumerate(axes):
        amp, z = ax.get_lines()[1].get_data()  # line 0 is the zero axis
        np.testing.assert_array_equal(z, pos[:, 2])  # vertical: height on the y axis
        np.testing.assert_allclose(amp, real_shape(modal.shapes[r]))
        assert f"{modal.natural_frequencies[r]:.4g} Hz" in ax.get_title()
    assert "1.20 %" in axes[0].get_title() and "n/a" in axes[2].get_title()
    assert axes[0].get_ylabel() == "z [m]"


def test_plot_mode_shapes_along_a_line_without_coords(results):
    modal = results["modal"]
    fig = figures.plot_mode_shapes(modal)
    ax = fig.axes[0]
    x, amp = ax.get_lines()[1].get_data()
    np.testing.assert_array_equal(x, np.arange(len(modal.points)))
    np.testing.assert_allclose(amp, real_shape(modal.shapes[0]))
    assert [t.get_text() for t in ax.get_xticklabels()] == ["s1", "s2", "s3", "s4"]  # shared parts cut


def test_plot_mode_shapes_of_a_real_modal_model(results):
    mod = pytest.importorskip("vibroscope.modal")
    ModalModel = getattr(mod, "ModalModel", None)
    if ModalModel is None:
        pytest.skip("vibroscope.modal has no ModalModel yet")
    fake = results["modal"]
    mm = ModalModel(natural_frequencies=fake.natural_frequencies, damping_ratios=fake.damping_ratios,
                    shapes=fake.shapes, points=fake.points, method="fdd")
    fig = mm.plot(syn.coords())
    assert len([a for a in fig.axes if a.get_visible()]) == 3


def test_plot_mode_shapes_one_line_per_direction(results):
    modal = results["modal"]
    # two sensors per height, measuring along x and y (as on the LUMO tower)
    coords = {p: {"xyz": (0.0, 0.0, float(1 + k // 2)), "direction": "x" if k % 2 == 0 else "y"}
              for k, p in enumerate(modal.points)}
    fig = figures.plot_mode_shapes(modal, coords)
    ax = fig.axes[0]
    solid = [ln for ln in ax.get_lines() if ln.get_linestyle() == "-" and ln.get_marker() == "o"]
    assert [ln.get_label() for ln in solid] == ["along x (real part)", "along y (real part)"]
    np.testing.assert_allclose(solid[0].get_data()[0], real_shape(modal.shapes[0])[[0, 2]])
    np.testing.assert_array_equal(solid[1].get_data()[1], [1.0, 2.0])


def test_plot_singular_values_marks_the_modes(results):
    f, S = results["sv"]
    modal = results["modal"]
    ax = figures.plot_singular_values(f, S, modal, true_frequencies=[2.8])
    marks = [ln for ln in ax.get_lines() if ln.get_label() == "picked modes"][0]
    np.testing.assert_array_equal(marks.get_data()[0], modal.natural_frequencies)
    np.testing.assert_allclose(marks.get_data()[1], np.interp(modal.natural_frequencies, f, 10 * np.log10(S[:, 0])))
    np.testing.assert_allclose(ax.get_lines()[0].get_data()[1], 10 * np.log10(S[:, 0]))
    assert "dB" in ax.get_ylabel() and "Hz" in ax.get_xlabel()


def test_sensor_geometry_forms():
    pts = ["a", "b"]
    pos, d, from_coords = sensor_geometry(pts, {"a": (0, 0, 1), "b": (0, 0, 3, "y")})
    np.testing.assert_array_equal(pos, [[0, 0, 1], [0, 0, 3]])
    np.testing.assert_array_equal(d, [[1, 0, 0], [0, 1, 0]])  # default x for a tower, explicit y
    assert from_coords
    with pytest.raises(ValueError, match="no coordinates"):
        sensor_geometry(pts, {"a": (0, 0, 1)})
    pos, d, from_coords = sensor_geometry(pts)
    np.testing.assert_array_equal(pos[:, 0], [0, 1])
    assert not from_coords


@pytest.mark.parametrize("qualname", [
    "figures.plot_spectrum", "figures.plot_frf", "figures.plot_mode_shapes", "figures.plot_singular_values",
    "figures.plot_signals", "figures.summary_figures", "rerun_view.log_analysis", "rerun_view.read_rrd",
    "rerun_view.mode_frames", "rerun_view.node_frames", "rerun_view.frequency_index",
    "rerun_view.channel_entity",
])
def test_public_viewer_functions_document_every_parameter(qualname):
    import importlib
    import inspect
    import re

    mod, name = qualname.split(".")
    fn = getattr(importlib.import_module(f"vibroscope.viewers.{mod}"), name)
    doc = inspect.getdoc(fn) or ""
    assert "Returns" in doc
    for p in inspect.signature(fn).parameters.values():
        assert re.search(rf"^\s*{p.name}\b|[ ,]{p.name}\b.*:", doc, re.M), f"{qualname}: {p.name!r} undocumented"
