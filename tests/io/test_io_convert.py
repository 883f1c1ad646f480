"""Converters: LUMO CSV (Wernitz et al. 2021, doi:10.25835/0027803), UFF 58 (pyuff samples,
MIT), Bouc-Wen .mat (Noel & Schoukens 2016), and synthetic files."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.cli import main
from vibroscope.io import mcap_info, read_mcap
from vibroscope.io.convert import convert_to_mcap, parse_columns, read_csv, read_mat, read_uff58


def test_parse_columns():
    assert parse_columns("0-3,7, 9-10") == [0, 1, 2, 3, 7, 9, 10]
    with pytest.raises(ValueError):
        parse_columns("3-1")


def test_lumo_acceptance(shared_data, tmp_path):
    src = shared_data / "lumo" / "data_lumo.csv"
    out = tmp_path / "lumo.mcap"
    assert main(["convert", str(src), str(out), "--fs", "1651", "--columns", "0-17", "--kind", "acceleration",
                 "--topic-prefix", "/lumo"]) == 0
    r = read_mcap(out)
    ref = np.loadtxt(src, delimiter=",")[:, :18].T
    assert r.n_channels == 18 and r.n_samples == 100000 and r.fs == 1651.0
    assert r.channels[0] == "/lumo/s01.linear_acceleration.x"
    assert np.array_equal(r.data, ref)
    assert all(r.meta["fast_path"].values())
    assert not any(tb["resampled"] for tb in r.meta["timebase"].values())


def test_uff58(shared_data, tmp_path):
    src = shared_data / "uff" / "MPSTD_Set001_2024_10_08.uff"
    s = read_uff58(src)
    assert s.n_channels == 4 and s.fs == 3200.0 and s.units == ("m/s^2",) * 4
    assert s.n_samples == 222400 and s.channels[0] == "MPS set1 Dof1"
    out, written = convert_to_mcap(src, tmp_path / "u.mcap")
    r = read_mcap(out, list(written.channels))
    assert r.fs == 3200.0 and np.array_equal(r.data, s.data)
    assert [t.schema_name for t in mcap_info(out).topics] == ["sensor_msgs/msg/Imu"] * 4


def test_csv_header_time_column_and_json(tmp_path):
    t = np.arange(500) / 200.0
    y = np.vstack([np.sin(t), np.cos(t)])
    p = tmp_path / "h.csv"
    np.savetxt(p, np.column_stack([t, y.T]), delimiter=",", header="time,volt,force", comments="")
    s = read_csv(p, time_column=0, units="V,N")
    assert s.channels == ("volt", "force") and s.fs == pytest.approx(200.0) and s.units == ("V", "N")
    with pytest.raises(ValueError, match="rate must be stated"):
        read_csv(p, columns="1")
    out, w = convert_to_mcap(p, tmp_path / "h.mcap", fs=200.0, columns="1,2", topic_prefix="/rig")
    assert w.channels == ("/rig.volt", "/rig.force")
    r = read_mcap(out, list(w.channels))
    assert np.array_equal(r.data, y) and r.units == ("", "N")  # units: "force" field -> N
    assert mcap_info(out).topics[0].message_encoding == "json"


def test_mat(shared_data, tmp_path):
    s = read_mat(shared_data / "boucwen" / "uval_multisine.mat", fs=750.0)
    assert s.channels == ("uval_multisine",) and s.n_samples == 8192
    from scipy.io import savemat

    savemat(tmp_path / "m.mat", {"fs": 512.0, "acc": np.ones((100, 2)), "label": "x"})
    m = read_mat(tmp_path / "m.mat", units="m/s2")
    assert m.fs == 512.0 and m.channels == ("acc[0]", "acc[1]") and m.units == ("m/s^2", "m/s^2")
    out, w = convert_to_mcap(tmp_path / "m.mat", tmp_path / "m.mcap", units="m/s2")
    assert w.channels[1] == "/vibroscope/s02.linear_acceleration.x"
    assert np.array_equal(read_mcap(out).data, m.data)
