"""Scale-out on Dask (vibroscope.fleet): per-log spectra accumulated over time ranges on a
LocalCluster equal csd_matrix of read_mcap of each log; the merged spectra are the segment-weighted
mean of the logs'; the fleet table and its CSV/JSON."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("dask.distributed")

from vibroscope.io import read_mcap, write_ros2_mcap  # noqa: E402
from vibroscope.signals import Signals  # noqa: E402
from vibroscope.spectral import csd_matrix  # noqa: E402

CHS = [f"/imu.linear_acceleration.{a}" for a in "xyz"]


def _log(path, n, seed, f0):
    """Three axes: a lightly damped resonance at f0 Hz driven by noise, plus noise."""
    import scipy.signal as ss

    rng = np.random.default_rng(seed)
    e = rng.standard_normal(n)
    b, a = ss.iirpeak(f0, 30.0, 500.0)
    y = ss.lfilter(b, a, e) * 10
    x = np.vstack([y + 0.1 * rng.standard_normal(n), 0.5 * y + 0.1 * rng.standard_normal(n),
                   -y + 0.1 * rng.standard_normal(n)])
    return write_ros2_mcap(path, Signals(data=x, fs=500.0, channels=CHS, t0=10.0 * seed), chunk_size=60_000)


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet")
    return [str(_log(d / f"robot{k}.mcap", n, k + 1, f0)) for k, (n, f0) in enumerate([(30_000, 40.0), (24_000, 41.0),
                                                                                          (36_000, 39.5)])]


@pytest.fixture(scope="module")
def client():
    from dask.distributed import Client

    from vibroscope.fleet import local_cluster

    with local_cluster(2) as lc, Client(lc) as c:
        yield c


def test_fleet_on_a_local_cluster_equals_in_memory(logs, client):
    from vibroscope.fleet import analyse_fleet, octave_bands

    res = analyse_fleet(logs, client=client, nperseg=1024, tasks_per_log=3)
    assert res.settings["tasks"] == 9 and res.settings["workers"] == 2
    refs = [csd_matrix(read_mcap(p), nperseg=1024) for p in logs]
    for p, ref in zip(logs, refs):
        G = res.per_log[p].csd()
        assert np.array_equal(G.n_averages, ref.n_averages)
        assert np.max(np.abs(G.G - ref.G)) <= 1e-12 * np.max(np.abs(ref.G))
    # merged: every segment of every log averaged once
    K = np.array([r.n_averages[0, 0] for r in refs], float)
    want = sum(k * r.G for k, r in zip(K, refs)) / K.sum()
    Gm = res.merged.csd()
    assert Gm.n_averages[0, 0] == K.sum()
    assert np.max(np.abs(Gm.G - want)) <= 1e-12 * np.max(np.abs(want))
    # the table: each log's resonance, and the RMS per octave band from its PSD
    for row, f0 in zip(res.rows, (40.0, 41.0, 39.5)):
        assert row.error == "" and len(row.natural_frequencies) >= 1
        assert min(abs(np.array(row.natural_frequencies) - f0)) < 0.5
    bands = octave_bands(500.0, 500.0 / 1024)
    assert res.rows[0].bands_hz == bands
    ref0 = refs[0]
    f = ref0.frequencies
    lo, hi = bands[-3]
    m = (f >= lo) & (f < hi)
    want_rms = np.sqrt(ref0.G[m, 0, 0].real.sum() * (f[1] - f[0]))
    assert res.rows[0].rms[0][len(bands) - 3] == pytest.approx(want_rms, rel=1e-12)


def test_tasks_carry_paths_and_ranges_not_arrays(logs, client, monkeypatch):
    from vibroscope import fleet

    sent = []
    real = client.submit

    def spy(fn, *args, **kw):
        sent.append((fn, args))
        return real(fn, *args, **kw)

    monkeypatch.setattr(client, "submit", spy)
    fleet.analyse_fleet(logs[:2], client=client, nperseg=512, tasks_per_log=2)
    reads = [args for fn, args in sent if fn is fleet._task]
    rows = [args for fn, args in sent if fn is fleet._log_row]
    assert len(reads) == 4 and len(rows) == 2 and len(sent) == 6
    for args in reads:
        assert not any(isinstance(a, np.ndarray) for a in args)
        path, channels, fs, t0, n, offsets, rng, settings = args
        assert path in logs and isinstance(rng, tuple) and 0 <= rng[0] < rng[1] <= n and fs == 500.0
        # each topic's range of stamp - log time (plain ints; 0 here: the writer logs at the stamps)
        assert offsets == (("/imu", 0, 0),)
        assert all(isinstance(v, (int, float, str, bool, type(None))) for v in settings.values())
    for path, bands, channels, fs, opts, *parts in rows:  # the per-log task gets its range tasks' futures
        assert path in logs and len(parts) == 2 and not any(isinstance(a, np.ndarray) for a in parts)


def test_table_csv_and_json(logs, client, tmp_path):
    from vibroscope.fleet import analyse_fleet

    res = analyse_fleet(logs, client=client, nperseg=1024, bands=[(30.0, 50.0), (100.0, 200.0)])
    rows = list(csv.DictReader(open(res.write_csv(tmp_path / "t.csv"))))
    assert [r["log"] for r in rows] == logs
    assert set(rows[0]) >= {"log", "n_samples", "duration_s", "modes_hz", "damping", "rms_30-50Hz", "rms_100-200Hz"}
    # the resonance band holds most of the motion
    assert all(float(r["rms_30-50Hz"]) > 3 * float(r["rms_100-200Hz"]) for r in rows)
    d = json.loads(res.write_json(tmp_path / "t.json").read_text())
    assert [x["log"] for x in d["logs"]] == logs and d["merged"]["n_segments"] == res.merged.accumulator.n_segments
    assert abs(d["merged"]["psd_peak_hz"][CHS[0]] - 40.0) < 1.5


def test_a_log_of_another_rate_is_left_out_and_one_a_little_off_resampled(logs, client, tmp_path):
    """The fleet's rate is the median log's: a 1000 Hz log among 500 Hz ones gets its row's error
    (it names the rates and --fs) and stays out of the merged spectra; a log at 501 Hz (its clock
    0.2 % off) is resampled onto 500 Hz and analysed (its resonance still found)."""
    from vibroscope.fleet import analyse_fleet

    x = np.random.default_rng(0).standard_normal((3, 5000))
    fast = str(write_ros2_mcap(tmp_path / "fast.mcap", Signals(data=x, fs=1000.0, channels=CHS, t0=1.0)))
    near = str(write_ros2_mcap(tmp_path / "near.mcap", Signals(data=read_mcap(logs[0]).data, fs=501.0, channels=CHS,
                                                               t0=2.0)))
    res = analyse_fleet([logs[0], fast, near, logs[1]], client=client, nperseg=1024)
    assert res.settings["fs"] == 500.0
    err = res.rows[1].error
    assert "rate 1000 Hz differs from the fleet's 500 Hz" in err and "--fs" in err
    assert res.settings["excluded"] == [fast] and not res.rows[2].error
    assert any("resampled onto the fleet's 500 Hz" in w and "near.mcap (501 Hz)" in w for w in res.settings["warnings"])
    modes = res.rows[2].natural_frequencies
    assert len(modes) and min(abs(f - 40.0 * 501 / 500) for f in modes) < 0.5
    assert res.merged.sources == (logs[0], near, logs[1])


def test_capstan_fleet_with_no_options(shared_data, client):
    """The five capstan logs (no Imu) as a fleet with no option: the first log chooses the moving
    joint-state fields; alternate_bagfile_0 is analysed, and each other log's row says why not
    (another rate, a field it lacks) instead of stopping the fleet."""
    from vibroscope.fleet import analyse_fleet

    paths = sorted(str(p) for p in (shared_data / "mcap" / "capstan").glob("*.mcap"))
    res = analyse_fleet(paths, client=client)
    rows = {r.log.rsplit("/", 1)[-1]: r for r in res.rows}
    assert not rows["alternate_bagfile_0.mcap"].error and rows["alternate_bagfile_0.mcap"].duration_s > 37
    assert all(c.startswith("/robot/joint_state.") for c in res.settings["channels"])
    assert "differs from the fleet's" in rows["torque_ripple_data_0.mcap"].error
    assert all(r.error for k, r in rows.items() if k != "alternate_bagfile_0.mcap")


def test_import_vibroscope_and_help_do_not_import_dask():
    code = ("import sys, vibroscope, vibroscope.stream, vibroscope.io.blocks, vibroscope.commands.analyse; "
            "from vibroscope.cli import build_parser; build_parser(); "
            "print(any(m == 'dask' or m.startswith(('dask.', 'distributed')) for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_cli_dask_with_a_scheduler_address(logs, client, tmp_path, capsys):
    """`vibroscope analyse --dask ADDRESS LOG LOG LOG`: the fleet table names every log with its mode
    (the resonances at 40, 41 and 39.5 Hz), and the JSON and the merged-spectra figure are written."""
    from vibroscope.cli import main

    addr = client.scheduler.address
    assert main(["analyse", "--dask", addr, *logs, "--out", str(tmp_path), "--nperseg", "1024"]) == 0
    out = capsys.readouterr().out
    assert f"fleet of 3 logs on {addr}" in out
    rows = list(csv.DictReader(open(tmp_path / "fleet.csv")))
    assert [r["log"] for r in rows] == logs
    for r, f0 in zip(rows, (40.0, 41.0, 39.5)):
        modes = [float(f) for f in r["modes_hz"].split(";") if f]
        assert modes and min(abs(f - f0) for f in modes) < 0.5, (r["log"], modes)
    assert json.loads((tmp_path / "fleet.json").read_text())["logs"][0]["log"] == logs[0]
    assert (tmp_path / "fleet_spectra.png").stat().st_size > 10_000
    # issue 21.3: the three are known as vibroscope's (a later run may replace them); a table of someone
    # else's in their place is refused, named, before any work, and kept
    from vibroscope.provenance import written_by_vibroscope

    assert all(written_by_vibroscope(tmp_path / n) for n in ("fleet.csv", "fleet.json", "fleet_spectra.png"))
    (tmp_path / "fleet.csv").write_text("my own table\n")
    assert main(["analyse", "--dask", addr, *logs, "--out", str(tmp_path), "--nperseg", "1024"]) == 1
    cap = capsys.readouterr()
    assert "not written by vibroscope" in cap.err and str(tmp_path / "fleet.csv") in cap.err
    assert "fleet of" not in cap.out and (tmp_path / "fleet.csv").read_text() == "my own table\n"


def test_a_given_rate_applies_to_every_log(logs, client):
    """`fs=` (the CLI's --fs) puts every log on that rate, not only the first."""
    from vibroscope.fleet import analyse_fleet

    res = analyse_fleet(logs, client=client, nperseg=512, fs=400.0)
    assert res.settings["fs"] == 400.0
    for row, n500 in zip(res.rows, (30_000, 24_000, 36_000)):
        assert abs(row.duration_s - n500 / 500.0) < 2.0 and row.n_samples == pytest.approx(row.duration_s * 400.0)


@pytest.fixture(scope="module")
def bad_logs(tmp_path_factory):
    """A garbage file, a log too short for a segment of 1024, and a log whose every segment of 1024
    touches a lost chunk (every third chunk damaged)."""
    import struct

    from vibroscope.io._scan import scan

    d = tmp_path_factory.mktemp("badfleet")
    garbage = d / "garbage.mcap"
    garbage.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    short = _log(d / "short.mcap", 600, 7, 40.0)
    holey = _log(d / "holey.mcap", 6000, 8, 40.0)
    data = bytearray(holey.read_bytes())
    for b in scan(holey).blocks[1:-1:3]:
        end = b.file_offset + 9 + struct.unpack_from("<Q", data, b.file_offset + 1)[0]
        data[end - 40] ^= 0x01
    holey.write_bytes(bytes(data))
    return str(garbage), str(short), str(holey)


def test_a_log_that_cannot_be_analysed_does_not_fail_the_fleet(logs, bad_logs, client):
    """Its row carries the error, it is left out of the merged spectra (said in the settings), and the
    good log's row and spectra are those of a fleet without it."""
    from vibroscope.fleet import analyse_fleet

    garbage, short, holey = bad_logs
    res = analyse_fleet([garbage, logs[0], short, holey], client=client, nperseg=1024, tasks_per_log=2)
    rows = {r.log: r for r in res.rows}
    assert [r.log for r in res.rows] == [garbage, logs[0], short, holey]
    assert rows[garbage].error.startswith("not analysed: cannot be planned: LogFormatError")
    assert garbage in rows[garbage].error
    assert "600 grid samples" in rows[short].error and rows[short].n_samples == 600
    assert "no segment" in rows[holey].error and rows[holey].n_samples == 6000
    for p in (garbage, short, holey):
        assert rows[p].natural_frequencies == () and np.isnan(np.array(rows[p].rms, float)).all()
    assert rows[logs[0]].error == "" and min(abs(np.array(rows[logs[0]].natural_frequencies) - 40.0)) < 0.5
    assert res.settings["excluded"] == [garbage, short, holey] and len(res.settings["warnings"]) == 3
    assert list(res.per_log) == [logs[0]] and res.merged.sources == (logs[0],)
    ref = csd_matrix(read_mcap(logs[0]), nperseg=1024)
    G = res.merged.csd()
    assert np.array_equal(G.n_averages, ref.n_averages) and np.max(np.abs(G.G - ref.G)) <= 1e-12 * np.max(np.abs(ref.G))
    table = res.to_rows()
    assert table[0]["error"].startswith("not analysed") and table[0]["rms_22.1-44.19Hz"] == ""
    assert json.loads(json.dumps(res.to_dict()))["logs"][3]["rms"][CHS[0]]["22.1-44.19Hz"] is None
    # every log unanalysable: refused, each named
    with pytest.raises(ValueError, match="no log of the fleet") as err:
        analyse_fleet([garbage, short], client=client, nperseg=1024)
    assert garbage in str(err.value) and short in str(err.value)


def test_default_resolution_from_the_median_log_not_the_shortest(logs, bad_logs, client):
    """With no nperseg, the median-length log chooses the Welch settings: one very short log does not
    coarsen every other log's resolution (on the capstan logs the shortest, 2.5 s, gave nperseg 16);
    it is left out with its reason instead."""
    from vibroscope.fleet import analyse_fleet
    from vibroscope.stream import stream_settings

    _garbage, short, _holey = bad_logs
    res = analyse_fleet([short, *logs], client=client)
    median_n = sorted(read_mcap(p).n_samples for p in logs)[1]
    assert res.settings["nperseg"] == stream_settings(median_n, 500.0)["nperseg"] > 600
    rows = {r.log: r for r in res.rows}
    assert "no Welch segment" in rows[short].error and res.settings["excluded"] == [short]
    for p in logs:
        assert rows[p].error == "" and min(abs(np.array(rows[p].natural_frequencies) - 40.0)) < 1.5


def test_a_failing_range_task_becomes_the_row_error(logs):
    """A range task returns its failure (here the log vanished after planning) instead of raising, and
    the per-log task turns it into the row's error."""
    from vibroscope.fleet import _Failed, _log_row, _task

    sett = dict(nperseg=512, noverlap=256, window="hann", detrend="constant", nfft=512)
    ok = _task(logs[0], tuple(CHS), 500.0, 10_000_000_000, 30_000, (("/imu", 0, 0),), (0, 4096), sett)
    gone = _task(logs[0] + ".gone", tuple(CHS), 500.0, 10_000_000_000, 30_000, (("/imu", 0, 0),), (4096 - 256, 8192),
                 sett)
    assert isinstance(gone, _Failed) and "LogFormatError" in gone.error and ".gone" in gone.error
    sp, row = _log_row(logs[0], ((30.0, 50.0),), tuple(CHS), 500.0, {}, ok, gone)
    assert sp is None and row.error.startswith("not analysed: LogFormatError") and row.natural_frequencies == ()
    sp, row = _log_row(logs[0], ((30.0, 50.0),), tuple(CHS), 500.0, {}, ok)
    assert sp is not None and sp.samples == 4096 and np.isfinite(np.array(row.rms, float)).all()


def test_capstan_log_with_stamps_46_s_before_logging_on_dask(shared_data, client):
    """The real log whose joint-state stamps lie 46 s before their log times (given twice): the tasks
    carry each topic's stamp offsets, so the ranges read their chunks; each log's spectra equal
    csd_matrix of read_mcap (before: every block NaN and the fleet failed)."""
    from vibroscope.fleet import analyse_fleet

    p = str(shared_data / "mcap" / "capstan" / "alternate_bagfile_0.mcap")
    chs = ["/robot/joint_state.velocity[0]", "/robot/joint_state.effort[0]"]
    res = analyse_fleet([p, p], client=client, channels=chs, nperseg=256, tasks_per_log=2)
    assert [r.error for r in res.rows] == ["", ""] and res.settings["excluded"] == []
    whole = read_mcap(p, chs)
    ref = csd_matrix(whole, nperseg=256)
    assert [r.n_samples for r in res.rows] == [whole.n_samples] * 2  # the log's grid, not its ranges' sum
    G = res.per_log[p].csd()
    assert np.array_equal(G.n_averages, ref.n_averages) and np.max(np.abs(G.G - ref.G)) <= 1e-12 * np.max(np.abs(ref.G))
    assert res.merged.accumulator.n_segments == 2 * ref.n_averages[0, 0]


def test_rows_carry_what_reading_noticed_and_the_json_is_plain(logs, bad_logs, client, tmp_path):
    """The holey log (every third chunk lost) analysed at nperseg 256: its row lists the lost chunks
    and missing samples (before: nothing in fleet.json); the settings are JSON lists, not Python
    reprs; a channel that never moves has no PSD peak (null, not the first bin)."""
    from vibroscope.fleet import analyse_fleet

    _garbage, _short, holey = bad_logs
    res = analyse_fleet([logs[0], holey], client=client, nperseg=256)
    rows = {r.log: r for r in res.rows}
    assert rows[logs[0]].warnings == ()
    w = " ".join(rows[holey].warnings)
    assert "missing" in w and "chunk" in w
    assert res.to_rows()[1]["warnings"] == " | ".join(rows[holey].warnings)
    d = json.loads(res.write_json(tmp_path / "f.json").read_text())
    assert d["settings"]["channels"] == CHS and d["logs"][1]["warnings"] == list(rows[holey].warnings)
    assert all(isinstance(b, list) and len(b) == 2 for b in d["settings"]["bands_hz"])
    flat = str(_log(tmp_path / "flat.mcap", 6000, 9, 40.0))
    x = read_mcap(flat)
    still = write_ros2_mcap(tmp_path / "still.mcap", Signals(data=np.vstack([x.data[:2], np.zeros((1, 6000))]),
                                                             fs=500.0, channels=CHS,
                                                             t0=90.0), chunk_size=60_000)
    d2 = analyse_fleet([str(still)], client=client, nperseg=256).to_dict()
    assert d2["merged"]["psd_peak_hz"][CHS[2]] is None and abs(d2["merged"]["psd_peak_hz"][CHS[0]] - 40.0) < 2.0


def test_cli_fleet_exits_1_when_no_log_was_analysed_without_error(logs, client, tmp_path, capsys):
    """Every log's identification fails (a band above the Nyquist frequency): the table is written,
    each row says why, and the exit status is 1 (before: 0)."""
    from vibroscope.cli import main

    rc = main(["analyse", "--dask", client.scheduler.address, logs[0], logs[1], "--out", str(tmp_path),
               "--nperseg", "512", "--fmin", "300", "--fmax", "400", "--no-figures"])
    cap = capsys.readouterr()
    assert rc == 1 and "none of the 2 logs was analysed without error" in cap.err
    assert len(list(csv.DictReader(open(tmp_path / "fleet.csv")))) == 2
