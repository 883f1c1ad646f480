"""Streaming analysis (vibroscope.stream): ranges split at segment boundaries merge into one pass
over the record; the modes of the demo structure from the spectra alone; and `vibroscope analyse`
of a log larger than its address-space limit completes by streaming where the whole read fails."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from vibroscope.io import read_mcap, write_ros2_mcap
from vibroscope.signals import Signals
from vibroscope.spectral import csd_matrix
from vibroscope.stream import accumulate_log, analyse_stream, merge_spectra, segment_ranges

CHS = [f"/imu.linear_acceleration.{a}" for a in "xyz"]
FORCE = "/actuator/force.wrench.force.x"
RESP = [f"/imu/m{i}.linear_acceleration.x" for i in (1, 2, 3)]


@pytest.fixture(scope="module")
def gappy_log(tmp_path_factory):
    """Correlated random data at 1000 Hz with one chunk lost (NaN in every channel)."""
    import struct

    from vibroscope.io._scan import scan

    rng = np.random.default_rng(5)
    e = rng.standard_normal((2, 30_000))
    x = np.vstack([e[0], 0.5 * e[0] + e[1], np.convolve(e[1], [1, 0.5, 0.25], "same")])
    d = tmp_path_factory.mktemp("stream")
    p = write_ros2_mcap(d / "a.mcap", Signals(data=x, fs=1000.0, channels=CHS, t0=5.0), chunk_size=50_000)
    data = bytearray(p.read_bytes())
    b = scan(p).blocks[7]
    end = b.file_offset + 9 + struct.unpack_from("<Q", data, b.file_offset + 1)[0]
    data[end - 40] ^= 0x01
    q = d / "lost.mcap"
    q.write_bytes(bytes(data))
    return q


@pytest.mark.parametrize("parts, block", [(1, 1 << 16), (3, 5000), (7, 1234)])
def test_ranges_merge_to_one_pass(gappy_log, parts, block):
    whole = read_mcap(gappy_log)
    assert np.isnan(whole.data).any()  # the lost chunk
    ref = csd_matrix(whole, nperseg=1024)
    n = whole.n_samples
    rngs = segment_ranges(n, 1024, 512, parts)
    spectra = [accumulate_log(gappy_log, nperseg=1024, samples=r, block_samples=block) for r in rngs]
    m = merge_spectra(spectra)
    G = m.csd()
    assert np.array_equal(G.n_averages, ref.n_averages)
    assert np.max(np.abs(G.G - ref.G)) <= 1e-12 * np.max(np.abs(ref.G))
    one = accumulate_log(gappy_log, nperseg=1024)  # one range, block by block
    assert np.max(np.abs(one.accumulator._sum - m.accumulator._sum)) <= 1e-12 * np.max(np.abs(one.accumulator._sum))
    assert m.samples == rngs[-1][1] and len(m.ranges) == len(rngs)
    lost = int(np.isnan(whole.data[0]).sum())
    assert any(f"{lost} of {n} grid samples missing" in w for w in one.warnings)
    assert any("chunk skipped" in w for w in one.warnings)
    assert spectra[0].accumulator.n_segments == one.accumulator.n_segments or parts > 1


def test_segment_ranges_hold_every_segment_once():
    n, nper, nov = 100_003, 1000, 250
    step = nper - nov
    n_seg = (n - nper) // step + 1
    for parts in (1, 2, 5, 1000):
        rngs = segment_ranges(n, nper, nov, parts)
        segs = [s for a, b in rngs for s in range(a // step, (b - nper) // step + 1)]
        assert segs == list(range(n_seg)) and all(a % step == 0 for a, _ in rngs)
        assert len(rngs) == min(parts, n_seg)
    assert segment_ranges(500, 1000, 500, 3) == []
    with pytest.raises(ValueError, match="parts="):
        segment_ranges(n, nper, nov, 0)


def test_stamps_long_before_their_log_times_stream(tmp_path):
    """Header stamps 45 s before their log times (as the capstan joint states): the streamed spectra,
    whole or split into ranges with the offsets carried (a fleet task), equal csd_matrix of read_mcap,
    and the resonance is found (before: every block NaN, "no non-constant response channel")."""
    import scipy.signal as ss

    from tests.io._io_helpers import write_imu_log

    fs, n, f0 = 200.0, 4000, 30.0
    rng = np.random.default_rng(12)
    b, a = ss.iirpeak(f0, 30.0, fs)
    x = ss.lfilter(b, a, rng.standard_normal(n)) * 10 + 0.1 * rng.standard_normal(n)
    t = (5_000_000_000 + np.arange(n) * 5_000_000).astype(np.int64)
    lt = t + 45_000_000_000 + rng.integers(0, 2_000_000, n)
    p = tmp_path / "lag.mcap"
    write_imu_log(p, {"/imu": (t, x)}, chunk_size=10_000, log_times={"/imu": lt})
    ref = csd_matrix(read_mcap(p, CHS), nperseg=256)
    one = accumulate_log(p, CHS, nperseg=256, block_samples=300)
    G = one.csd()
    assert np.array_equal(G.n_averages, ref.n_averages) and np.max(np.abs(G.G - ref.G)) <= 1e-12 * np.max(np.abs(ref.G))
    from vibroscope.io.blocks import open_grid

    g = open_grid(p, CHS)
    rngs = segment_ranges(g.n_samples, 256, 128, 3)
    m = merge_spectra([accumulate_log(p, CHS, fs=g.fs, t0_ns=g.t0_ns, n_samples=g.n_samples, samples=r, nperseg=256,
                                      stamp_offsets=g.stamp_offsets, block_samples=300) for r in rngs])
    assert np.max(np.abs(m.csd().G - ref.G)) <= 1e-12 * np.max(np.abs(ref.G))
    an = analyse_stream(p, outputs=CHS[:2])
    assert min(abs(an.modal.natural_frequencies - f0)) < 0.5


@pytest.fixture(scope="module")
def demo_log(tmp_path_factory):
    from vibroscope.commands.demo import make_demo_log

    p = tmp_path_factory.mktemp("demo") / "demo.mcap"
    model, _sig = make_demo_log(p, duration=40.0)
    return p, model.modes()


def test_analyse_stream_finds_the_demo_modes(demo_log):
    p, truth = demo_log
    an = analyse_stream(p, input=FORCE, outputs=RESP)
    assert an.frf is not None and an.frf.coherence.shape == (an.frf.frequencies.size, 3)
    assert len(an.modal.natural_frequencies) == 3
    assert np.allclose(an.modal.natural_frequencies, truth.natural_frequencies, rtol=0.005)
    assert np.allclose(an.modal.damping_ratios, truth.damping_ratios, rtol=0.1)
    # output-only: EFDD on the response CSD finds the same three modes
    oo = analyse_stream(p, outputs=RESP)
    assert oo.frf is None and oo.modal.method in ("efdd", "fdd")
    assert np.allclose(oo.modal.natural_frequencies, truth.natural_frequencies, rtol=0.02)
    with pytest.raises(ValueError, match="time series"):
        analyse_stream(p, outputs=RESP, method="ssi")


def test_cli_stream_option(demo_log, tmp_path, capsys):
    from vibroscope.cli import main

    p, truth = demo_log
    js = tmp_path / "s.json"
    out_dir = tmp_path / "out"
    assert main(["analyse", str(p), "--stream", "--input", FORCE, "--outputs", *RESP, "--json", str(js),
                 "--out", str(out_dir)]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0].startswith(f"streaming {p} block by block: --stream")
    d = json.loads(js.read_text())
    assert d["settings"]["streamed"] is True
    assert np.allclose([m["frequency_hz"] for m in d["modes"]], truth.natural_frequencies, rtol=0.005)
    # the figures and the recording of the spectra, FRFs and modes; none of the time series
    figs = out_dir / f"{p.stem}_analyse_figures"
    assert sorted(f.name for f in figs.glob("*.png")) == ["frf.png", "frf_synthesis.png", "modes.png", "psd.png",
                                                          "singular_values.png", "stabilization.png"]
    from vibroscope.viewers.rerun_view import read_rrd

    ents = read_rrd(out_dir / f"{p.stem}_analyse.rrd")
    assert {"/psd", "/frf", "/modes", "/csd"} <= {"/" + e.split("/")[1] for e in ents}
    assert not [e for e in ents if e.startswith("/signals")]
    assert main(["analyse", str(p), "--max-memory", "1MB", "--outputs", *RESP, "--no-rrd", "--no-figures"]) == 0
    assert "more than the memory budget 1 MiB" in capsys.readouterr().out


_CHILD = textwrap.dedent("""
    import resource, sys
    mode, log, extra_mb = sys.argv[1], sys.argv[2], float(sys.argv[3])
    import numpy, scipy.signal, scipy.linalg  # everything the run imports, before the limit
    import vibroscope.cli, vibroscope.commands.analyse, vibroscope.stream, vibroscope.io.blocks, vibroscope.pipeline
    import vibroscope.modal.automatic, vibroscope.modal.fdd, vibroscope.modal.selection
    import vibroscope.spectral
    vibroscope.spectral.csd_matrix(numpy.ones((2, 64)), 1.0, nperseg=32)  # loads numba (llvmlite maps ~GBs)

    def peak():
        for line in open("/proc/self/status"):
            if line.startswith("VmPeak"):
                return int(line.split()[1]) * 1024

    lim = int(peak() + extra_mb * 2**20)
    resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
    args = ["analyse", log, "--no-rrd", "--no-figures"]
    if mode == "whole":
        args += ["--max-memory", "100GB"]  # forbid the switch to streaming
    sys.exit(vibroscope.cli.main(args))
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS and /proc are Linux's")
def test_log_larger_than_the_address_space_limit_streams(tmp_path):
    """A 150 MB log under an address-space limit 100 MB above what the imports take: reading it
    whole fails (the file alone does not fit), `vibroscope analyse` switches to streaming by
    itself and completes."""
    rng = np.random.default_rng(2)
    n = 400_000
    x = np.cumsum(rng.standard_normal((3, n)), axis=1) * 1e-3 + rng.standard_normal((3, n))
    log = write_ros2_mcap(tmp_path / "big.mcap", Signals(data=x, fs=1000.0, channels=CHS, t0=1.0), compression="none")
    assert log.stat().st_size > 140e6
    script = tmp_path / "child.py"
    script.write_text(_CHILD)
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1",
               NUMBA_NUM_THREADS="1", PYTHONPATH=str(Path(__file__).resolve().parents[1]))

    def child(mode):
        return subprocess.run([sys.executable, str(script), mode, str(log), "100"], capture_output=True, text=True,
                              env=env, timeout=120, cwd=tmp_path)

    whole = child("whole")
    assert whole.returncode == 1 and ("memory" in whole.stderr.lower() or "allocate" in whole.stderr.lower()), \
        whole.stderr[-2000:]
    streamed = child("stream")
    assert streamed.returncode == 0, streamed.stderr[-2000:]
    assert "streaming" in streamed.stdout and "more than the memory budget" in streamed.stdout
    assert f"3 channels x {n} samples at 1000 Hz" in streamed.stdout


def test_capstan_joint_states_stamped_46_s_before_logging_stream(shared_data):
    """A real ROS 2 log (capstan, mcap-bag-parser's data) whose /robot/joint_state header stamps lie
    about 46 s before their log times: streamed, its spectra are csd_matrix of read_mcap's record
    (before: every block NaN and "no non-constant response channel")."""
    from vibroscope.io.blocks import open_grid

    p = shared_data / "mcap" / "capstan" / "alternate_bagfile_0.mcap"
    chs = ["/robot/joint_state.velocity[0]", "/robot/joint_state.effort[0]"]
    g = open_grid(p, chs)
    (topic, lo, hi), = g.stamp_offsets
    assert topic == "/robot/joint_state" and -47e9 < lo <= hi < -45e9
    whole = read_mcap(p, chs)
    assert np.array_equal(np.concatenate([b.data for b in g.blocks(500)], axis=1), whole.data, equal_nan=True)
    an = analyse_stream(p, outputs=chs)
    ref = csd_matrix(whole, nperseg=an.spectra.settings["nperseg"])
    G = an.spectra.csd()
    assert np.array_equal(G.n_averages, ref.n_averages) and np.max(np.abs(G.G - ref.G)) <= 1e-12 * np.max(np.abs(ref.G))
    assert len(an.modal.natural_frequencies) >= 1


# ---- automatic channels and gaps: `--stream` with no options on logs without an Imu topic ----

def _joint_log(path, *, gaps=False):
    """A JSON log with no Imu: /robot/joint (two moving fields of a 35 Hz resonance, a constant one
    and a sequence counter) at 400 Hz, and a less busy-scoring /robot/temp (one field); with
    `gaps`, NaN in every field for 40 samples every 700."""
    import scipy.signal as ss

    rng = np.random.default_rng(11)
    n, fs = 24_000, 400.0
    b, a = ss.iirpeak(35.0, 25.0, fs)
    y = ss.lfilter(b, a, rng.standard_normal(n)) * 5
    x = np.vstack([y + 0.05 * rng.standard_normal(n), -0.7 * y + 0.05 * rng.standard_normal(n),
                   np.full(n, 3.0), np.arange(n, dtype=float), 20 + 0.01 * rng.standard_normal(n)])
    if gaps:
        for s in range(300, n, 700):
            x[:, s : s + 40] = np.nan
    names = ["/robot/joint.pos", "/robot/joint.vel", "/robot/joint.mode_value", "/robot/joint.seq", "/robot/temp.t"]
    return write_ros2_mcap(path, Signals(data=x, fs=fs, channels=names, t0=3.0), chunk_size=40_000)


def test_stream_without_channels_takes_the_moving_fields_of_the_busiest_topic(tmp_path, monkeypatch):
    """No Imu: the streamed analysis with no channel given chooses what the whole read chooses
    (the busiest topic's measurement fields that move: not the constant one, not the counter) from
    the summary and the first and last chunks, with the same messages counted when the summary has
    no statistics; its spectra are csd_matrix of read_mcap of those channels."""
    from vibroscope.commands.analyse import analyse_log
    from vibroscope.io import blocks
    from vibroscope.io.blocks import open_grid

    p = _joint_log(tmp_path / "joint.mcap")
    g = open_grid(p)
    assert g.channels == ("/robot/joint.pos", "/robot/joint.vel")
    assert any("channels chosen automatically" in w and "/robot/joint" in w for w in g.warnings)
    whole = analyse_log(p, method="fdd")
    assert tuple(whole.signals.channels) == g.channels  # the whole read's choice
    plan = blocks._summary_plan
    monkeypatch.setattr(blocks, "_summary_plan", lambda path, fh, *a: (*plan(path, fh, *a)[:4], None))
    assert open_grid(p).channels == g.channels  # counts estimated from the sampled chunks
    monkeypatch.undo()
    an = analyse_stream(p)
    ref = csd_matrix(read_mcap(p, list(g.channels)), nperseg=an.spectra.settings["nperseg"])
    G = an.spectra.csd()
    assert np.array_equal(G.n_averages, ref.n_averages) and np.max(np.abs(G.G - ref.G)) <= 1e-12 * np.max(np.abs(ref.G))
    assert min(abs(f - 35.0) for f in an.modal.natural_frequencies) < 0.5


def test_streamed_nperseg_shortened_to_fit_between_gaps_as_the_whole_read(tmp_path):
    """Gaps every 700 samples: the automatic segment (4096 samples for the record's length) holds
    none; the streamed analysis halves it as analyse_signals does (_nperseg_for: 8 segments free
    of gaps) from the stretches the first pass saw, and reads the log again with it."""
    from vibroscope.pipeline import _nperseg_for
    from vibroscope.stream import stream_settings

    p = _joint_log(tmp_path / "gappy.mcap", gaps=True)
    chs = ["/robot/joint.pos", "/robot/joint.vel"]
    whole = read_mcap(p, chs)
    first = stream_settings(whole.n_samples, whole.fs)["nperseg"]
    want = _nperseg_for(whole, first)
    assert want < first
    an = analyse_stream(p, outputs=chs)
    assert an.spectra.settings["nperseg"] == want
    assert any(f"nperseg {first} -> {want}" in w for w in an.spectra.warnings)
    ref = csd_matrix(whole, nperseg=want)
    assert np.array_equal(an.spectra.csd().n_averages, ref.n_averages)
    with pytest.raises(ValueError, match="free of gaps"):
        analyse_stream(p, outputs=chs, nperseg=1024)  # given: kept, and no segment fits


@pytest.mark.parametrize("seed", range(40))
def test_gap_free_stretches_across_blocks_count_the_segments(seed):
    """_GapFree over random block splits gives the stretches of the whole mask, and
    _fitting_segments counts exactly the segments (50 % overlap) free of gaps."""
    from vibroscope.signals import true_runs
    from vibroscope.stream import _fitting_segments, _GapFree

    rng = np.random.default_rng(seed)
    n = int(rng.integers(50, 3000))
    good = np.ones(n, bool)
    for _ in range(int(rng.integers(0, 12))):
        a = int(rng.integers(0, n))
        good[a : a + int(rng.integers(1, 60))] = False
    start = int(rng.integers(0, 100))
    acc = _GapFree(start)
    cuts = np.sort(rng.choice(np.arange(1, n), size=min(n - 1, int(rng.integers(0, 8))), replace=False))
    for piece in np.split(good, cuts):
        acc.add(piece)
    runs = acc.result()
    a, b = true_runs(good)
    keep = b - a >= 16
    assert np.array_equal(runs, np.stack([a[keep], b[keep]], axis=1) + start)
    for nper in (16, 32, 50, 128, 512):
        step = nper - nper // 2
        brute = sum(good[i : i + nper].all() for i in range(0, n - nper + 1, step))
        assert _fitting_segments(runs, start, nper) == brute


def test_capstan_logs_stream_with_no_options(shared_data):
    """Every capstan log (joint states, no Imu) streams with no channel and no setting given: the
    moving fields of the busiest topic, as the whole read chooses them (alternate_bagfile_0: the
    same 17 fields), and for the gappy logs a segment short enough to fit between the gaps."""
    from vibroscope.commands.analyse import stream_report_text
    from vibroscope.io.select import auto_channels

    d = shared_data / "mcap" / "capstan"
    for name in ("alternate_bagfile_0", "bagfile_0", "controlled_data_0", "torque_ripple_data_0",
                 "uncontrolled_data_0"):
        an = analyse_stream(d / f"{name}.mcap")
        text = stream_report_text(an)
        assert " nan " not in text, text  # a damping not estimated reads "-", and says why
        if not np.isfinite(an.modal.damping_ratios).all():
            assert "zeta -: not estimated" in text
        chosen = an.spectra.channels
        assert chosen and set(chosen) <= set(auto_channels(d / f"{name}.mcap").channels), name
        assert an.csd.G.shape[1] >= 1 and np.isfinite(an.psd.values).any(), name
        if name == "alternate_bagfile_0":
            whole = read_mcap(d / f"{name}.mcap", list(auto_channels(d / f"{name}.mcap").channels))
            moving = [c for c in whole.channels if np.nanmax(whole[c]) > np.nanmin(whole[c])]
            assert list(chosen) == moving[:32]
        if name == "torque_ripple_data_0":  # 20 Hz with 715 gaps: the automatic 2048 holds no segment
            assert an.spectra.settings["nperseg"] < 256


def test_refinement_for_the_damping_stops_where_segments_no_longer_fit_between_gaps(tmp_path):
    """Force and two responses of a 35 Hz resonance (ζ ≈ 1.7 %) with 40 samples missing every 700:
    the automatic segment is shortened to 512 to fit between the gaps; the damping refinement,
    which doubles it, stops there (1024 holds no segment: before, the run failed with "no response
    channel has a segment of nperseg=1024 free of gaps"), and the mode is found."""
    import scipy.signal as ss

    rng = np.random.default_rng(3)
    n, fs = 24_000, 400.0
    f = rng.standard_normal(n)
    b, a = ss.iirpeak(35.0, 30.0, fs)
    y = ss.lfilter(b, a, f) * 20 + 0.01 * rng.standard_normal(n)
    x = np.vstack([f, y, 0.5 * y + 0.01 * rng.standard_normal(n)])
    for s in range(300, n, 700):
        x[:, s : s + 40] = np.nan
    chs = ["/ft.wrench.force.x", "/imu.linear_acceleration.x", "/imu.linear_acceleration.y"]
    p = write_ros2_mcap(tmp_path / "refine.mcap", Signals(data=x, fs=fs, channels=chs, units=["N", "m/s^2", "m/s^2"],
                                                          t0=2.0))
    an = analyse_stream(p, input=chs[0], outputs=chs[1:])
    assert an.spectra.settings["nperseg"] == 512
    assert len(an.modal.natural_frequencies) == 1 and abs(an.modal.natural_frequencies[0] - 35.0) < 0.5


def test_streamed_value_beyond_any_measurement_is_missing(tmp_path):
    """One 1e300 sample: the streamed spectra are those of the log with that sample missing (before:
    the squares overflowed and EFDD stopped with "Eigenvalues did not converge")."""
    rng = np.random.default_rng(8)
    x = rng.standard_normal((3, 20_000))
    bad, nan = x.copy(), x.copy()
    bad[1, 7000], nan[1, 7000] = 1e300, np.nan
    a = accumulate_log(write_ros2_mcap(tmp_path / "huge.mcap", Signals(data=bad, fs=1000.0, channels=CHS, t0=1.0)),
                       nperseg=1024)
    b = accumulate_log(write_ros2_mcap(tmp_path / "nan.mcap", Signals(data=nan, fs=1000.0, channels=CHS, t0=1.0)),
                       nperseg=1024)
    assert np.array_equal(a.csd().G, b.csd().G) and np.array_equal(a.csd().n_averages, b.csd().n_averages)
    assert any("1 samples beyond" in w for w in a.warnings)
    analyse_stream(tmp_path / "huge.mcap")  # completes
