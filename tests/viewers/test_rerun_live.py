"""Live progressive view (issue #9, target 5) and the decimated time series of a recording (target 6),
read back with rerun's own reader; the stream through gRPC is received by rerun's own server
(``rerun --serve-grpc --save``, headless, localhost only)."""

from __future__ import annotations

import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

rr = pytest.importorskip("rerun", reason="rerun-sdk is not installed (pip install vibroscope[rerun])")

from vibroscope.signals import Signals  # noqa: E402
from vibroscope.spectral import csd_matrix, frf  # noqa: E402
from vibroscope.viewers.rerun_live import LiveView, record_blocks, stream_blocks  # noqa: E402
from vibroscope.viewers.rerun_view import (  # noqa: E402
    channel_entity,
    envelope_indices,
    frequency_index,
    log_analysis,
    read_rrd,
)

FS = 200.0
NPERSEG = 256
CHANNELS = ("/shaker/force.x", "/acc/a1.z", "/acc/a2.z", "/acc/a3.z")


def _record(n: int = 12_000, seed: int = 1) -> Signals:
    """A white-noise force through three FIR paths plus output noise (FRF and coherence vary)."""
    rng = np.random.default_rng(seed)
    f = rng.standard_normal(n)
    y = [np.convolve(f, rng.standard_normal(8), mode="same") + 0.2 * rng.standard_normal(n) for _ in range(3)]
    return Signals(data=np.vstack([f, *y]), fs=FS, channels=CHANNELS, units=["N", "m/s^2", "m/s^2", "m/s^2"], t0=3.0)


def _db(v, fac=10.0):
    v = np.asarray(v, float)
    return np.where(v > 0, fac * np.log10(np.where(v > 0, v, 1.0)), np.nan)


def _close(a, b, rtol=1e-12):
    """Equal to `rtol` of the largest magnitude (entries near zero compared absolutely)."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * np.nanmax(np.abs(b)), equal_nan=True)


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    sig = _record()
    path = tmp_path_factory.mktemp("live") / "live.rrd"
    rec = rr.RecordingStream("vibroscope-test")
    rec.save(str(path))
    view = stream_blocks(record_blocks(sig, 500), rec, input=CHANNELS[0], nperseg=NPERSEG, every_blocks=5,
                         every_s=None)
    rec.flush()
    rec.disconnect()
    return sig, view, read_rrd(path), path


def test_final_spectra_equal_the_offline_ones(live):
    sig, view, _, _ = live
    G = csd_matrix(sig, nperseg=NPERSEG)
    H = frf(sig, CHANNELS[0], nperseg=NPERSEG)
    last = view.last
    assert last.final and last.n_averages == G.settings["n_averages"] == (sig.n_samples - NPERSEG) // 128 + 1
    _close(last.csd.G, G.G)
    _close(last.psd.values, G.psd().values)
    _close(last.frf.H, H.H)
    _close(last.frf.coherence, H.coherence)
    np.testing.assert_array_equal(last.csd.n_averages, G.n_averages)


def test_logged_final_spectra_equal_the_offline_ones(live):
    sig, _, data, _ = live
    G = csd_matrix(sig, nperseg=NPERSEG)
    H = frf(sig, CHANNELS[0], nperseg=NPERSEG)
    ftl, idx = frequency_index(G.frequencies)
    for k, ch in enumerate(CHANNELS):
        ent = data[channel_entity("psd", ch)]
        np.testing.assert_array_equal(ent[ftl], idx)
        _close(ent["Scalars:scalars"], _db(G.psd().values[k]))
    for o, ch in enumerate(CHANNELS[1:]):
        _close(data[channel_entity("frf/magnitude_db", ch)]["Scalars:scalars"], _db(np.abs(H.H[:, o, 0]), 20))
        _close(data[channel_entity("frf/phase_deg", ch)]["Scalars:scalars"], np.degrees(np.angle(H.H[:, o, 0])))
        _close(data[channel_entity("frf/coherence", ch)]["Scalars:scalars"], H.coherence[:, o])


def test_intermediate_spectra_are_welch_of_the_record_so_far(live):
    sig, view, data, _ = live
    ent = data[channel_entity("live/psd", CHANNELS[1])]
    counts = np.asarray(ent["averages"])
    # a refresh every 5 blocks of 500 samples: 2500, 5000, 7500, 10000 samples, then the final 12000
    n_read = np.array([2500, 5000, 7500, 10000, 12000])
    np.testing.assert_array_equal(counts, (n_read - NPERSEG) // 128 + 1)
    np.testing.assert_array_equal(ent["time"], np.round(n_read / FS * 1e9).astype(np.int64))
    assert [r.n_averages for r in view.refreshes] == list(counts)
    coh = data[channel_entity("live/frf/coherence", CHANNELS[2])]["BarChart:values"]
    for r, n in enumerate(n_read):
        part = Signals(data=sig.data[:, :n], fs=FS, channels=CHANNELS, units=sig.units)
        G = csd_matrix(part, nperseg=NPERSEG)
        _close(np.asarray(ent["BarChart:values"][r]["buffer"]), _db(G.psd().values[1]))
        _close(np.asarray(coh[r]["buffer"]), frf(G, CHANNELS[0]).coherence[:, 1])
    axis = data[channel_entity("live/psd", CHANNELS[1])]["static"]["BarChart:abscissa"][0]
    np.testing.assert_array_equal(axis["buffer"], np.fft.rfftfreq(NPERSEG, 1 / FS))
    n_avg = data["/live/n_averages"]["Scalars:scalars"]
    np.testing.assert_array_equal(n_avg, counts)


def test_blueprint_shows_the_live_tab_on_the_time_timeline(live):
    bp = read_rrd(live[3], blueprint=True)
    views = {cols["ViewBlueprint:space_origin"][-1]: cols["ViewBlueprint:class_identifier"][-1]
             for cols in bp.values() if "ViewBlueprint:class_identifier" in cols}
    for ch in CHANNELS:
        assert views[channel_entity("signals", ch)] == "TimeSeries"
        assert views[channel_entity("live/psd", ch)] == "BarChart"
    assert views[channel_entity("live/frf/coherence", CHANNELS[1])] == "BarChart"
    assert CHANNELS[0] not in {o.split("/live/frf/coherence")[-1] for o in views if "coherence" in o}
    assert views["/psd"] == views["/frf/magnitude_db"] == "TimeSeries"
    assert bp["/time_panel"]["TimePanelBlueprint:timeline"][-1] == "time"


def test_time_series_arrive_block_by_block(live):
    sig, _, data, _ = live
    for k, ch in enumerate(CHANNELS):
        ent = data[channel_entity("signals", ch)]
        np.testing.assert_array_equal(ent["time"], np.round(np.arange(sig.n_samples) / FS * 1e9).astype(np.int64))
        np.testing.assert_array_equal(ent["Scalars:scalars"], sig.data[k])  # blocks of 500 <= 2000 points: all


def test_blocks_beyond_block_points_are_enveloped_exactly(tmp_path):
    sig = _record(6000)
    rec = rr.RecordingStream("vibroscope-test")
    rec.save(str(tmp_path / "env.rrd"))
    view = LiveView(rec, fs=FS, channels=CHANNELS, nperseg=NPERSEG, block_points=100, every_blocks=2)
    view.run(record_blocks(sig, 1500))
    rec.flush()
    rec.disconnect()
    data = read_rrd(tmp_path / "env.rrd")
    for k, ch in enumerate(CHANNELS):
        ent = data[channel_entity("signals", ch)]
        i = np.round(np.asarray(ent["time"]) * FS / 1e9).astype(int)  # sample index of each point
        np.testing.assert_array_equal(ent["Scalars:scalars"], sig.data[k, i])  # true samples at true times
        assert i.size <= 4 * 100
        for b in range(4):  # each block's 50 bins of 30 samples: their min and max are drawn
            x = sig.data[k, 1500 * b: 1500 * (b + 1)].reshape(50, 30)
            got = set(i[(i >= 1500 * b) & (i < 1500 * (b + 1))])
            assert {1500 * b + 30 * j + int(np.argmax(x[j])) for j in range(50)} <= got
            assert {1500 * b + 30 * j + int(np.argmin(x[j])) for j in range(50)} <= got
    # no block since the last refresh: the final one replaces it (one live row per average count)
    assert [r.n_averages for r in view.refreshes] == [(3000 - 256) // 128 + 1, (6000 - 256) // 128 + 1]


def test_blocks_must_follow_each_other():
    sig = _record(2000)
    rec = rr.RecordingStream("vibroscope-test")
    rec.memory_recording()
    view = LiveView(rec, fs=FS, channels=CHANNELS, nperseg=NPERSEG)
    blocks = list(record_blocks(sig, 500))
    view.update(blocks[0])
    with pytest.raises(ValueError, match="does not follow the previous block"):
        view.update(blocks[2])
    with pytest.raises(ValueError, match="differ from the view"):
        view.update(sig.select(CHANNELS[:2]))
    with pytest.raises(ValueError, match="input='/nope'"):
        LiveView(rec, fs=FS, channels=CHANNELS, input="/nope")
    with pytest.raises(ValueError, match="no complete segment"):
        LiveView(rec, fs=FS, channels=CHANNELS, nperseg=NPERSEG).refresh()
    assert view.close() is not None  # 500 samples: 2 segments of 256
    with pytest.raises(ValueError, match="closed"):
        view.update(blocks[1])


# -- decimated time series of log_analysis (target 6) ---------------------------------------------

def test_envelope_indices_keep_every_bins_extremes():
    rng = np.random.default_rng(3)
    x = rng.standard_normal(10_001)
    x[[17, 5000, 9999]] = [50.0, -60.0, 70.0]  # spikes: one sample wide
    x[200:260] = np.nan
    i = envelope_indices(x, 1000)
    assert i.size <= 1000 and np.all(np.diff(i) > 0) and np.all(np.isfinite(x[i]))
    assert {17, 5000, 9999} <= set(i)
    w = -(-x.size // 500)  # 500 bins of 21 samples
    for b in range(0, x.size, w):
        seg = x[b: b + w]
        if np.isfinite(seg).any():
            assert b + int(np.nanargmax(seg)) in i and b + int(np.nanargmin(seg)) in i
    assert not any(200 <= j < 260 for j in i)
    np.testing.assert_array_equal(envelope_indices(x[:900], 1000), np.flatnonzero(np.isfinite(x[:900])))  # short
    np.testing.assert_array_equal(envelope_indices(x, None), np.flatnonzero(np.isfinite(x)))
    with pytest.raises(ValueError, match="max_points=1"):
        envelope_indices(x, 1)


def test_long_record_is_logged_as_its_envelope(tmp_path):
    rng = np.random.default_rng(4)
    n = 250_000
    data = rng.standard_normal((2, n))
    data[0, 123_457] = 40.0
    data[1, 77_000:77_100] = np.nan
    sig = Signals(data=data, fs=1000.0, channels=["/imu.a.x", "/imu.a.y"], units=["m/s^2"] * 2)
    d = read_rrd(log_analysis(signals=sig, rrd_path=tmp_path / "long.rrd", max_points=10_000))
    for k, ch in enumerate(sig.channels):
        ent = d[channel_entity("signals", ch)]
        i = np.round(np.asarray(ent["time"]) / 1e6).astype(int)  # 1 kHz: the time in ms is the index
        v = ent["Scalars:scalars"]
        assert v.size <= 10_000
        if k == 1:  # the samples, then the Clear that breaks the line at the gap's first missing sample
            np.testing.assert_array_equal(i[v.size:], [77_000])
            i = i[: v.size]
        np.testing.assert_array_equal(v, data[k, i])
        assert v.max() == np.nanmax(data[k]) and v.min() == np.nanmin(data[k])
    assert d[channel_entity("signals", "/imu.a.x")]["Scalars:scalars"].max() == 40.0
    gaps = d[channel_entity("signals", "gaps")]
    assert "77–77.1 s (100 samples)" in gaps["TextLog:text"][0]
    assert "decimated for display" in d["/about"]["static"]["TextDocument:text"][0]


# -- through gRPC, received by rerun's own server --------------------------------------------------

def _rerun_binary() -> str | None:
    try:
        import rerun_cli
    except ImportError:
        return shutil.which("rerun")
    exe = Path(rerun_cli.__file__).parent / "rerun"
    return str(exe) if exe.is_file() else shutil.which("rerun")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_analyse_connect_streams_to_a_grpc_server(tmp_path):
    exe = _rerun_binary()
    if exe is None:
        pytest.skip("no rerun binary (rerun_cli) to receive the stream")
    from vibroscope.io import write_ros2_mcap

    sig = _record(8000)
    acc = Signals(data=sig.data[1:], fs=FS, channels=["/imu.linear_acceleration.x", "/imu.linear_acceleration.y",
                                     "/imu.linear_acceleration.z"], units=["m/s^2"] * 3)
    log = write_ros2_mcap(tmp_path / "live.mcap", acc)
    port = _free_port()
    got = tmp_path / "received.rrd"
    srv = subprocess.Popen([exe, "--serve-grpc", "--port", str(port), "--bind", "127.0.0.1", "--save", str(got)],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        t = time.monotonic()
        while time.monotonic() - t < 20:  # wait for the server to listen
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.1)
        else:
            pytest.skip("rerun --serve-grpc did not start listening")
        cmd = [sys.executable, "-m", "vibroscope.cli", "analyse", str(log), "--connect",
               f"rerun+http://127.0.0.1:{port}/proxy", "--nperseg", str(NPERSEG), "--no-rrd", "--no-figures",
               "--out", str(tmp_path)]
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr
        time.sleep(0.5)
    finally:
        srv.send_signal(signal.SIGINT)
        try:
            srv.wait(10)
        except subprocess.TimeoutExpired:
            srv.kill()
            srv.wait()
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a received stream has no footer
        data = read_rrd(got)
    from vibroscope.io import read_mcap

    offline = csd_matrix(read_mcap(log, list(acc.channels)), nperseg=NPERSEG)
    ftl, _ = frequency_index(offline.frequencies)
    for k, ch in enumerate(acc.channels):
        _close(data[channel_entity("psd", ch)]["Scalars:scalars"], _db(offline.psd().values[k]))
        counts = np.asarray(data[channel_entity("live/psd", ch)]["averages"])
        assert counts.size >= 3 and np.all(np.diff(counts) > 0) and counts[-1] == offline.settings["n_averages"]
        assert data[channel_entity("signals", ch)]["Scalars:scalars"].size == acc.n_samples


def test_connect_without_a_viewer_is_one_clear_error(tmp_path, capsys):
    from vibroscope.cli import main
    from vibroscope.io import write_ros2_mcap
    from vibroscope.commands._live import stream_log

    sig = Signals(data=_record(2000).data[1:], fs=FS, channels=[f"/imu.linear_acceleration.{c}" for c in "xyz"],
                  units=["m/s^2"] * 3)
    log = write_ros2_mcap(tmp_path / "x.mcap", sig)
    url = f"rerun+http://127.0.0.1:{_free_port()}/proxy"  # nothing listens there
    t = time.monotonic()
    with pytest.raises(ConnectionError, match=re.escape(f"no rerun viewer listening at {url}")):
        stream_log(log, url=url)
    assert main(["analyse", str(log), "--connect", url, "--no-rrd", "--no-figures", "--out", str(tmp_path)]) == 1
    assert f"no rerun viewer listening at {url}" in capsys.readouterr().err
    assert time.monotonic() - t < 20
