"""The rerun recording of an analysis, read back with rerun's own reader (rerun.chunk.RrdReader)."""

from __future__ import annotations

import numpy as np
import pytest

rr = pytest.importorskip("rerun")

import _viewers_synthetic as syn  # noqa: E402
from vibroscope.viewers.rerun_view import (  # noqa: E402
    channel_entity,
    frequency_index,
    log_analysis,
    mode_entity,
    read_rrd,
)


@pytest.fixture(scope="module")
def analysis():
    psd, csd, frf, _ = syn.spectra()
    return {"signals": syn.signals(), "psd": psd, "csd": csd, "frf": frf, "modal": syn.modal()}


@pytest.fixture(scope="module")
def rrd(analysis, tmp_path_factory):
    path = tmp_path_factory.mktemp("rrd") / "analysis.rrd"
    out = log_analysis(**analysis, coords=syn.coords(), rrd_path=path, recording_name="synthetic",
                       recording_id="rec-1")
    assert out == path
    return path


@pytest.fixture(scope="module")
def data(rrd):
    return read_rrd(rrd)


def test_file_is_complete_and_holds_one_recording_and_a_blueprint(rrd):
    from rerun.chunk import RrdReader
    from rerun_bindings import check_for_rrd_footer

    assert check_for_rrd_footer(str(rrd))
    reader = RrdReader(rrd)
    recs = reader.recordings()
    assert len(recs) == 1
    assert recs[0].application_id == "vibroscope" and recs[0].recording_id == "rec-1"
    assert len(reader.blueprints()) == 1
    assert rr.get_global_data_recording() is None  # an explicit RecordingStream, not the global one


def test_time_series_equal_the_signals(analysis, data):
    sig = analysis["signals"]
    t_ns = np.round(np.arange(sig.n_samples) / sig.fs * 1e9).astype(np.int64)
    for k, ch in enumerate(sig.channels):
        ent = data[channel_entity("signals", ch)]
        np.testing.assert_array_equal(ent["time"], t_ns)
        np.testing.assert_array_equal(ent["Scalars:scalars"], sig.data[k])  # float64, exact
        assert ent["static"]["SeriesLines:names"][0] == f"{ch} [m/s^2]"
    assert channel_entity("signals", sig.channels[0]) == "/signals/acc/s1.z"


def test_psd_in_db_on_the_millihertz_timeline(analysis, data):
    psd = analysis["psd"]
    name, idx = frequency_index(psd.frequencies)
    assert name == "frequency_mHz"
    np.testing.assert_array_equal(idx, np.round(psd.frequencies * 1000))
    for k, ch in enumerate(psd.channels):
        ent = data[channel_entity("psd", ch)]
        np.testing.assert_array_equal(ent["frequency_mHz"], idx)
        v = psd.values[k]
        expected = np.where(v > 0, 10 * np.log10(np.where(v > 0, v, 1)), np.nan)
        np.testing.assert_array_equal(ent["Scalars:scalars"], expected)
        # back to the PSD itself
        np.testing.assert_allclose(10 ** (ent["Scalars:scalars"][1:] / 10), v[1:], rtol=1e-12)


def test_frf_magnitude_phase_coherence(analysis, data):
    frf = analysis["frf"]
    for o, out in enumerate(frf.outputs):
        h = frf.H[:, o, 0]
        mag = data[channel_entity("frf/magnitude_db", out)]["Scalars:scalars"]
        np.testing.assert_allclose(mag[1:], 20 * np.log10(np.abs(h[1:])), rtol=0, atol=1e-12)
        np.testing.assert_array_equal(data[channel_entity("frf/phase_deg", out)]["Scalars:scalars"],
                                      np.degrees(np.angle(h)))
        np.testing.assert_array_equal(data[channel_entity("frf/coherence", out)]["Scalars:scalars"],
                                      frf.coherence[:, o])


def test_csd_singular_values(analysis, data):
    S = np.linalg.svd(analysis["csd"].G, compute_uv=False)
    got = data["/csd/singular_values/s1"]["Scalars:scalars"]
    np.testing.assert_allclose(got, 10 * np.log10(S[:, 0]), atol=1e-9)
    assert "/csd/singular_values/s3" in data and "/csd/singular_values/s4" not in data


def test_given_singular_values_are_logged_as_computed(analysis, data, tmp_path):
    """The analysis' own singular values (``singular_values=``) are what is logged, and equal the
    recording's own SVD to rounding (1e-12 of the largest; the Hermitian eigen-solver of
    :func:`singular_values` and the SVD differ there); values of another frequency axis are not
    used."""
    from vibroscope.modal.fdd import SingularValues, singular_values

    sv = singular_values(analysis["csd"])
    d = read_rrd(log_analysis(csd=analysis["csd"], singular_values=sv, rrd_path=tmp_path / "sv.rrd"))
    for k in range(3):
        got = d[f"/csd/singular_values/s{k + 1}"]["Scalars:scalars"]
        np.testing.assert_array_equal(got, 10 * np.log10(sv.S[:, k]))
        ref = data[f"/csd/singular_values/s{k + 1}"]["Scalars:scalars"]
        np.testing.assert_allclose(10 ** (got / 10), 10 ** (ref / 10), rtol=0, atol=1e-12 * sv.S.max())
    other = SingularValues(sv.frequencies + 1.0, 2 * sv.S)  # another axis: the recording computes its own
    d = read_rrd(log_analysis(csd=analysis["csd"], singular_values=other, rrd_path=tmp_path / "o.rrd"))
    np.testing.assert_allclose(d["/csd/singular_values/s1"]["Scalars:scalars"],
                               data["/csd/singular_values/s1"]["Scalars:scalars"], atol=1e-9)


@pytest.mark.parametrize("frame", [0, 10, 27])
def test_mode_shape_points_are_the_displaced_sensors(analysis, data, frame):
    modal = analysis["modal"]
    coords = syn.coords()
    pos = np.array([coords[p]["xyz"] for p in modal.points])
    dirs = np.array([coords[p]["direction"] for p in modal.points])
    scale = 0.15 * 6.0  # 15 % of the 6 m height spanned by the sensors
    for r, f in enumerate(modal.natural_frequencies):
        ent = data[mode_entity(r, f)]
        np.testing.assert_array_equal(ent["animation"], np.arange(40))
        phi = modal.shapes[r] / np.abs(modal.shapes[r]).max()
        disp = np.real(phi * np.exp(2j * np.pi * frame / 40))
        expected = pos + scale * disp[:, None] * dirs
        got = ent["Points3D:positions"][frame]
        assert got.dtype == np.float32
        np.testing.assert_array_equal(got, expected.astype(np.float32))
        strip = ent["LineStrips3D:strips"][frame]  # joins the points bottom to top
        np.testing.assert_array_equal(strip, expected[np.argsort(pos[:, 2])].astype(np.float32))
        und = data[mode_entity(r, f) + "/undeformed"]["static"]
        np.testing.assert_array_equal(und["Points3D:positions"], pos.astype(np.float32))
    assert mode_entity(0, 2.82) == "/modes/mode_1_2.82Hz"


def test_mode_table_and_about(analysis, data):
    table = data["/modes/table"]["static"]["TextDocument:text"][0]
    assert "| 1 | 2.8200 | 1.200 |" in table and "| 3 | 13.1000 | n/a |" in table
    about = data["/about"]["static"]["TextDocument:text"][0]
    assert "frequency_mHz" in about and "t0 = 12.5 s" in about
    assert data["/__properties"]["static"]["RecordingInfo:name"][0] == "synthetic"


def test_blueprint_holds_the_views(analysis, rrd):
    bp = read_rrd(rrd, blueprint=True)
    views = {}
    containers = []
    for ent, cols in bp.items():
        if "ViewBlueprint:class_identifier" in cols:
            views[cols["ViewBlueprint:space_origin"][-1]] = cols["ViewBlueprint:class_identifier"][-1]
        if "ContainerBlueprint:container_kind" in cols:
            containers.append(cols.get("ContainerBlueprint:display_name", [None])[-1])
    for ch in analysis["signals"].channels:
        assert views[channel_entity("signals", ch)] == "TimeSeries"
    for origin in ("/psd", "/csd/singular_values", "/frf/magnitude_db", "/frf/phase_deg", "/frf/coherence"):
        assert views[origin] == "TimeSeries"
    for r, f in enumerate(analysis["modal"].natural_frequencies):
        assert views[mode_entity(r, f)] == "3D"
    assert views["/modes/table"] == "TextDocument"
    assert {"Time series (timeline: time)", "Spectra (timeline: frequency_mHz)",
            "FRF (timeline: frequency_mHz)", "Mode shapes (timeline: animation)"} <= set(containers)
    assert bp["/time_panel"]["TimePanelBlueprint:timeline"][-1] == "animation"


def test_points_on_a_line_without_coords_and_signals_only(tmp_path, analysis):
    p = log_analysis(modal=analysis["modal"], rrd_path=tmp_path / "m.rrd")
    d = read_rrd(p)
    und = d[mode_entity(0, analysis["modal"].natural_frequencies[0]) + "/undeformed"]["static"]
    np.testing.assert_array_equal(und["Points3D:positions"][:, 0], np.arange(4))
    # a second analysis is a second, separate recording
    q = log_analysis(signals=analysis["signals"], rrd_path=tmp_path / "s.rrd")
    d2 = read_rrd(q)
    assert not any(k.startswith("/modes") for k in d2) and "/signals/acc/s4.z" in d2
    assert read_rrd(q, blueprint=True)["/time_panel"]["TimePanelBlueprint:timeline"][-1] == "time"


def test_frequency_index_falls_back_to_microhertz():
    name, idx = frequency_index(np.arange(5) * 2e-4)
    assert name == "frequency_uHz"
    np.testing.assert_array_equal(idx, [0, 200, 400, 600, 800])


def test_needs_a_sink():
    with pytest.raises(ValueError, match="rrd_path or spawn"):
        log_analysis(signals=syn.signals())


def test_two_sensors_at_one_location_move_one_strip_vertex(tmp_path, analysis):
    modal = analysis["modal"]
    # sensors 1, 2 at height 1 m (x and y), sensors 3, 4 at 2 m (x and y)
    coords = {p: {"xyz": (0.0, 0.0, float(1 + k // 2)), "direction": "xy"[k % 2]}
              for k, p in enumerate(modal.points)}
    d = read_rrd(log_analysis(modal=modal, coords=coords, rrd_path=tmp_path / "xy.rrd"))
    ent = d[mode_entity(0, modal.natural_frequencies[0])]
    phi = modal.shapes[0] / np.abs(modal.shapes[0]).max()
    scale = 0.15 * 1.0
    disp = scale * np.real(phi)  # frame 0
    expected = np.array([[disp[0], disp[1], 1.0], [disp[2], disp[3], 2.0]], dtype=np.float32)
    np.testing.assert_array_equal(ent["LineStrips3D:strips"][0], expected)
    np.testing.assert_array_equal(ent["Points3D:positions"][0][1], np.float32([0.0, disp[1], 1.0]))
