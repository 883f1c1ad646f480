"""Converters: LUMO CSV (Wernitz et al. 2021, doi:10.25835/0027803), UFF 58 (pyuff samples,
MIT), Bouc-Wen .mat (Noel & Schoukens 2016), and synthetic files."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.cli import main
from vibroscope.errors import LogFormatError
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
    # no fs: the header's "time" column is found and gives the rate
    s2 = read_csv(p, columns="1")
    assert s2.channels == ("volt",) and s2.fs == pytest.approx(200.0) and np.array_equal(s2.data[0], y[0])
    with pytest.raises(ValueError, match="time column"):
        read_csv(p, columns="0,1")  # the time column is not a channel
    out, w = convert_to_mcap(p, tmp_path / "h.mcap", fs=200.0, columns="1,2", topic_prefix="/rig", units="force=N")
    assert w.channels == ("/rig.volt", "/rig.force") and w.units == ("", "N")
    r = read_mcap(out, list(w.channels))
    assert np.array_equal(r.data, y) and r.units[1] == "N"
    assert mcap_info(out).topics[0].message_encoding == "json"
    assert _units_in_mcap(out) == {"/rig": {"force": "N"}}  # volt: unit unknown, no entry


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


# --- issue 8: options by name, a clear demand for --fs, units stored, input never overwritten ----------


def _units_in_mcap(path):
    """{topic: units} as stored in the Channel records' metadata (read with mcap's own reader)."""
    import json

    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        chans = make_reader(fh).get_summary().channels.values()
    return {c.topic: json.loads(c.metadata["vibroscope.units"]) for c in chans}


def test_convert_csv_without_rate_asks_for_fs(tmp_path, capsys):
    p = tmp_path / "data.csv"
    np.savetxt(p, np.arange(20.0).reshape(10, 2), delimiter=",")
    out = tmp_path / "out.mcap"
    assert main(["convert", str(p), str(out), "--columns", "0-1"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "data.csv" in err and "--fs" in err and "no time column was found" in err
    assert not out.exists()
    # with the rate it converts; a named time column is also accepted
    assert main(["convert", str(p), str(out), "--columns", "0-1", "--fs", "10"]) == 0
    assert read_mcap(out, ["/vibroscope.c0", "/vibroscope.c1"]).fs == 10.0
    s = read_csv(p, time_column=0)
    assert s.fs == pytest.approx(0.5) and s.channels == ("c1",)


def _mat_pair(tmp_path):
    """Two .mat files with the same variables written in different orders."""
    from scipy.io import savemat

    rng = np.random.default_rng(3)
    force, acc, volt = rng.normal(size=(3, 64))
    savemat(tmp_path / "a.mat", {"fs": 128.0, "force": force, "acc": acc, "volt": volt})
    savemat(tmp_path / "b.mat", {"volt": volt, "acc": acc, "fs": 128.0, "force": force})
    return force, acc, volt


@pytest.mark.parametrize(
    "channels, units",
    [
        ("force,acc", "force=N,acc=m/s^2"),
        ("force,acc", "N,m/s^2"),  # positional: in the --channels order
        (None, "force=N,acc=m/s^2,volt=V"),
    ],
)
def test_mat_channels_and_units_by_name(tmp_path, channels, units):
    force, acc, volt = _mat_pair(tmp_path)
    results = []
    for name in ("a", "b"):
        sig = read_mat(tmp_path / f"{name}.mat", channels=channels, units=units)
        labels = dict(zip(sig.channels, sig.units))
        assert labels["force"] == "N" and labels["acc"] == "m/s^2"
        assert np.array_equal(sig.data[sig.channels.index("force")],
                              force)
        assert np.array_equal(sig.data[sig.channels.index("acc")], acc)
        if channels:
            assert sig.channels == ("force", "acc")
        else:
            assert labels["volt"] == "V" and sig.n_channels == 3
        results.append(labels)
    assert results[0] == results[1]


def test_convert_mat_same_command_same_labels(tmp_path):
    force, acc, _ = _mat_pair(tmp_path)
    stored = []
    for name in ("a", "b"):
        out = tmp_path / f"{name}.mcap"
        assert main(["convert", str(tmp_path / f"{name}.mat"), str(out), "--channels", "force,acc",
                     "--units", "N,m/s^2"]) == 0
        stored.append(_units_in_mcap(out))
        r = read_mcap(out, ["/vibroscope.force", "/vibroscope/s02.linear_acceleration.x"])
        assert np.array_equal(r.data, np.vstack([force, acc]))
    assert stored[0] == stored[1] == {"/vibroscope": {"force": "N"},
                                      "/vibroscope/s02": {"linear_acceleration.x": "m/s^2"}}


def test_mat_positional_units_without_channels_is_an_error(tmp_path, capsys):
    _mat_pair(tmp_path)
    with pytest.raises(ValueError, match=r"not meaningful.*--channels"):
        read_mat(tmp_path / "a.mat", units="N,m/s^2,V")
    assert main(["convert", str(tmp_path / "a.mat"), str(tmp_path / "x.mcap"), "--units", "N,m/s^2,V"]) == 1
    assert "name=unit" in capsys.readouterr().err and not (tmp_path / "x.mcap").exists()
    # one unit for all is unambiguous
    assert read_mat(tmp_path / "a.mat", units="V").units == ("V", "V", "V")


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"channels": "force,nope"}, r"no channel 'nope'.*\['force', 'acc', 'volt'\]"),
        ({"units": "force=N,speed=m/s"}, r"names no channel 'speed'.*\['force', 'acc', 'volt'\]"),
        ({"channels": "force,acc", "units": "N,V,m"}, r"3 units .* for 2 channels"),
        ({"units": "force=N,V"}, "not both"),
        ({"channels": "force,force"}, "selected twice"),
    ],
)
def test_bad_names_and_units(tmp_path, kw, match):
    _mat_pair(tmp_path)
    with pytest.raises(ValueError, match=match):
        read_mat(tmp_path / "a.mat", **kw)


def test_csv_channels_and_units_by_header_name(tmp_path):
    rng = np.random.default_rng(0)
    y = rng.normal(size=(50, 3))
    p = tmp_path / "h.csv"
    np.savetxt(p, y, delimiter=",", header="acc,force,volt", comments="")
    s = read_csv(p, fs=100.0, channels="volt,acc", units="acc=m/s2,volt=V")
    assert s.channels == ("volt", "acc") and s.units == ("V", "m/s^2")
    assert np.array_equal(s.data, y[:, [2, 0]].T)
    with pytest.raises(ValueError, match=r"no channel 'accel'.*\['acc', 'force', 'volt'\]"):
        read_csv(p, fs=100.0, channels="accel")
    # without a header the names are c<column>
    q = tmp_path / "n.csv"
    np.savetxt(q, y, delimiter=",")
    s = read_csv(q, fs=100.0, channels="c2,c0", units="N,V")
    assert s.channels == ("c2", "c0") and s.units == ("N", "V") and np.array_equal(s.data, y[:, [2, 0]].T)
    from scipy.io import savemat

    savemat(tmp_path / "x.mat", {"fs": 10.0, "a": y[:, 0]})
    with pytest.raises(ValueError, match="selects CSV columns"):
        convert_to_mcap(tmp_path / "x.mat", tmp_path / "x.mcap", columns="0")


def test_uff_channels_and_units_by_name(shared_data, tmp_path):
    src = shared_data / "uff" / "MPSTD_Set001_2024_10_08.uff"
    s = read_uff58(src, channels="MPS set1 Dof3,MPS set1 Dof1", units="MPS set1 Dof1=g")
    assert s.channels == ("MPS set1 Dof3", "MPS set1 Dof1") and s.units == ("m/s^2", "g")
    full = read_uff58(src)
    assert np.array_equal(s.data, full.data[[2, 0]])
    with pytest.raises(ValueError, match=r"no channel 'Dof9'.*MPS set1 Dof1"):
        read_uff58(src, channels="Dof9")


def test_convert_refuses_to_overwrite_its_input(tmp_path, capsys):
    p = tmp_path / "in.csv"
    np.savetxt(p, np.ones((10, 2)), delimiter=",")
    before = p.read_bytes()
    assert main(["convert", str(p), str(p), "--fs", "10"]) == 1
    assert "is the input IN" in capsys.readouterr().err  # refused by the command's output check, before any work
    with pytest.raises(ValueError, match="is the input file"):
        convert_to_mcap(p, tmp_path / "." / ".." / tmp_path.name / "in.csv", fs=10.0)
    link = tmp_path / "link.mcap"
    link.symlink_to(p)
    with pytest.raises(ValueError, match="is the input file"):
        convert_to_mcap(p, link, fs=10.0)
    assert p.read_bytes() == before


def test_interrupted_convert_leaves_no_output(tmp_path, monkeypatch):
    from vibroscope.io import _ros2

    p = tmp_path / "in.csv"
    np.savetxt(p, np.ones((10, 2)), delimiter=",")
    out = tmp_path / "out.mcap"
    out.write_bytes(b"previous complete file")

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(_ros2, "encode_fixed", boom)
    with pytest.raises(KeyboardInterrupt):
        convert_to_mcap(p, out, fs=10.0, kind="acceleration")
    assert out.read_bytes() == b"previous complete file"
    assert sorted(f.name for f in tmp_path.iterdir()) == ["in.csv", "out.mcap"]  # no temporary left behind
    monkeypatch.undo()
    convert_to_mcap(p, out, fs=10.0, kind="acceleration")
    assert read_mcap(out).n_samples == 10


def test_units_stored_in_every_channel_record(tmp_path):
    """Imu, WrenchStamped and JSON channels all carry their units; read_mcap still reads the file."""
    from vibroscope.io.mcap_write import write_json_mcap, write_ros2_mcap
    from vibroscope.signals import Signals

    rng = np.random.default_rng(1)
    sig = Signals(data=rng.normal(size=(5, 40)), fs=100.0,
                  channels=["/imu/a.linear_acceleration.x", "/imu/a.angular_velocity.z", "/ft.wrench.force.x",
                   "/rig.pressure", "volt"],
                  units=["m/s^2", "", "N", "Pa", ""])
    out = write_ros2_mcap(tmp_path / "r.mcap", sig)
    assert _units_in_mcap(out) == {
        "/imu/a": {"linear_acceleration.x": "m/s^2", "angular_velocity.z": "rad/s"},  # rad/s: the Imu definition
        "/ft": {"wrench.force.x": "N"},
        "/rig": {"pressure": "Pa"},
        "/signals": {},  # unit unknown: no entry, nothing guessed
    }
    r = read_mcap(out, list(sig.channels[:4]))
    assert np.array_equal(r.data, sig.data[:4]) and r.fs == 100.0
    out = write_json_mcap(tmp_path / "j.mcap", sig)
    assert _units_in_mcap(out)["/imu/a"] == {"linear_acceleration.x": "m/s^2"}  # JSON: only the given unit


def test_acceleration_kind_refuses_other_units(tmp_path):
    p = tmp_path / "h.csv"
    np.savetxt(p, np.ones((10, 2)), delimiter=",", header="acc,force", comments="")
    with pytest.raises(ValueError, match="'force' has unit 'N'"):
        convert_to_mcap(p, tmp_path / "o.mcap", fs=10.0, units="force=N", kind="acceleration")


def test_hostile_csv_inputs(tmp_path):
    """Each fault is an error naming the file (and line); a missing cell stays NaN."""
    p = tmp_path / "x.csv"
    for text in ("", "a,b\n"):
        p.write_text(text)
        with pytest.raises(LogFormatError, match=r"x\.csv: no data rows"):
            read_csv(p, fs=10.0)
    p.write_text("a,b\n1,2\n3,x\n")
    with pytest.raises(LogFormatError, match=r"x\.csv: line 3: not a numeric"):
        read_csv(p, fs=10.0)
    p.write_text("1,2\n3,\n5,6\n")
    with pytest.warns(UserWarning, match="1 empty cells read as missing samples"):
        s = read_csv(p, fs=10.0)
    np.testing.assert_array_equal(s.data, [[1, 3, 5], [2, np.nan, 6]])
    with pytest.raises(LogFormatError, match="no such input file"):
        convert_to_mcap(tmp_path / "nope.csv", tmp_path / "o.mcap", fs=1.0)
    p.write_text("1,2\n3,4\n")
    with pytest.raises(ValueError, match="is a directory"):
        convert_to_mcap(p, tmp_path, fs=1.0)
    with pytest.raises(ValueError, match="does not exist"):
        convert_to_mcap(p, tmp_path / "no" / "o.mcap", fs=1.0)


def test_time_column_gaps_are_refused_not_filled(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("t,a\n0.0,1\n0.1,2\n0.2,3\n0.6,4\n0.7,5\n")
    with pytest.raises(ValueError, match=r"'t' does not step uniformly: line 4 -> 5 goes from 0.2 s to 0.6 s"):
        read_csv(p)
    p.write_text("t,a\n0.0,1\n0.1,2\n0.2,3\n")
    with pytest.raises(ValueError, match="disagrees with the time column 't'"):
        read_csv(p, fs=50.0)
    s = read_csv(p, fs=10.0)  # found even with fs, and consistent with it
    assert s.channels == ("a",) and s.fs == 10.0
    s = read_csv(p, fs=10.0, columns="0,1")  # listed as data: it is data
    assert s.channels == ("t", "a")


def test_units_pairs_may_name_channels_not_selected(tmp_path):
    """One --units list serves several commands: pairs for channels not converted are ignored,
    but a name the file does not have is an error."""
    from scipy.io import savemat

    savemat(tmp_path / "l.mat", {"fs": 10.0, "force": np.arange(10.0), "acc": np.ones(10), "long": np.ones(20)})
    s = read_mat(tmp_path / "l.mat", channels="force", units="acc=m/s^2,force=N")
    assert s.channels == ("force",) and s.units == ("N",)
    s = read_mat(tmp_path / "l.mat")
    assert s.channels == ("force", "acc") and s.meta["skipped_variables"] == {"long": 20}
    with pytest.raises(ValueError, match=r"no channel 'zz'; the file's channels are \['force', 'acc', 'long'\]"):
        read_mat(tmp_path / "l.mat", units="zz=N")
    p = tmp_path / "h.csv"
    np.savetxt(p, np.ones((5, 3)), delimiter=",", header="a,b,c", comments="")
    with pytest.raises(ValueError, match=r"no channel 'c' \(not among the columns read\)"):
        read_csv(p, fs=1.0, columns="0,1", channels="c")
    assert read_csv(p, fs=1.0, columns="0,1", units="c=V,a=N").units == ("N", "")


def test_nan_and_inf_cells_are_said(tmp_path):
    """Cells written as inf or beyond float64 (1e400) are missing samples: read as they are, with a
    warning naming the count and the first line (before: silently); a ragged row's error counts
    lines as the file does (it said "line 7: ... at row 5")."""
    p = tmp_path / "a.csv"
    rows = [f"{k / 100},{np.sin(k / 7)}" for k in range(200)]
    rows[50], rows[120] = "0.5,inf", "1.2,1e400"
    p.write_text("t,acc\n" + "\n".join(rows) + "\n")
    with pytest.warns(UserWarning, match=r"2 cells are NaN or ±Inf .* first at line 52"):
        read_csv(p)
    q = tmp_path / "b.csv"
    q.write_text("t,acc\n" + "\n".join(rows[:5] + ["0.05"] + rows[6:10]) + "\n")
    with pytest.raises(LogFormatError, match=r"line 7: not a numeric CSV file \(.*at line 7"):
        read_csv(q)
