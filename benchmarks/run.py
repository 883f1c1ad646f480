"""vibroscope's speed and memory suite.

Every figure is a ratio against a baseline measured in the same run on the same data, so results
compare across machines: ``python benchmarks/run.py [--quick] [--json out.json]``.

Cases
-----
csd_matrix      full cross-spectral matrix: our one-pass engine vs pairwise ``scipy.signal.csd``
csd_threads     the engine with 2 worker threads vs 1
csd_memory      peak traced memory (tracemalloc) of the engine vs pairwise scipy
mcap_read       reading Imu accelerations from a ROS 2 MCAP: ``read_mcap`` (numpy chunk fast path)
                vs decoding every message with ``mcap_ros2`` (the library's own reader)
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import scipy.signal


def _best(fn, repeat=3):
    best = np.inf
    for _ in range(repeat):
        gc.collect()
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def _peak_mem(fn):
    gc.collect()
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def bench_csd(n_ch: int, n: int) -> list[dict]:
    from vibroscope.spectral import csd_matrix

    rng = np.random.default_rng(0)
    x = rng.standard_normal((n_ch, n))
    kw = dict(fs=1000.0, nperseg=1024)

    def ours():
        return csd_matrix(x, **kw)

    def ours2():
        return csd_matrix(x, workers=2, **kw)

    def pairwise():
        out = np.empty((513, n_ch, n_ch), complex)
        for i in range(n_ch):
            for j in range(i, n_ch):
                out[:, i, j] = scipy.signal.csd(x[i], x[j], **kw)[1]
                out[:, j, i] = np.conj(out[:, i, j])
        return out

    err = np.max(np.abs(ours().G - pairwise())) / np.max(np.abs(pairwise()))
    t_ours, t_scipy, t_two = _best(ours), _best(pairwise, 1), _best(ours2)
    m_ours, m_scipy = _peak_mem(ours), _peak_mem(pairwise)
    size = f"{n_ch} ch x {n:.0e} samples"
    return [
        dict(case="csd_matrix", size=size, ours_s=t_ours, baseline_s=t_scipy, speedup=t_scipy / t_ours,
             max_rel_err=float(err), baseline="pairwise scipy.signal.csd"),
        dict(case="csd_threads", size=size, ours_s=t_two, baseline_s=t_ours, speedup=t_ours / t_two,
             baseline="csd_matrix workers=1"),
        dict(case="csd_memory", size=size, ours_MB=m_ours / 1e6, baseline_MB=m_scipy / 1e6,
             memory_ratio=m_scipy / m_ours, baseline="pairwise scipy.signal.csd"),
    ]


def bench_mcap(n_msgs: int) -> list[dict]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from vibroscope import Signals
    from vibroscope.io import read_mcap, write_ros2_mcap

    rng = np.random.default_rng(1)
    chans = [f"/imu/a.linear_acceleration.{c}" for c in "xyz"]
    sig = Signals(rng.standard_normal((3, n_msgs)), 1000.0, chans, ["m/s^2"] * 3, t0=1.7e9)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "imu.mcap"
        write_ros2_mcap(path, sig)

        def ours():
            return read_mcap(path, chans)

        def library():
            with open(path, "rb") as f:
                r = make_reader(f, decoder_factories=[DecoderFactory()])
                vals = [(m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z)
                        for _, _, _, m in r.iter_decoded_messages(topics=["/imu/a"])]
            return np.array(vals)

        got = ours().data
        ref = library().T
        assert np.array_equal(got, ref), "fast path differs from the library decoder"
        t_ours, t_lib = _best(ours), _best(library, 1)
    return [dict(case="mcap_read", size=f"{n_msgs} Imu messages", ours_s=t_ours, baseline_s=t_lib,
                 speedup=t_lib / t_ours, ours_msgs_per_s=n_msgs / t_ours, baseline_msgs_per_s=n_msgs / t_lib,
                 baseline="mcap_ros2 iter_decoded_messages")]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="small sizes (seconds)")
    p.add_argument("--json", type=Path, help="write the results as JSON")
    p.add_argument("--samples", type=float, help="samples per channel of the CSD cases (default 1e6; 1e5 with --quick)")
    a = p.parse_args(argv)
    n = int(a.samples) if a.samples else (10**5 if a.quick else 10**6)
    rows = bench_csd(10, n)
    rows += bench_mcap(20_000 if a.quick else 200_000)
    for r in rows:
        print("  ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()))
    if a.json:
        a.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
