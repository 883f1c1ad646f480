"""Scale-out on Dask (issue #9, target 4): :func:`vibroscope.fleet.analyse_fleet` of a multi-file job
on a ``LocalCluster`` of 2 single-threaded worker processes against 1, in the same run (cluster
start-up not timed; best of `--repeat`); the in-process sequential accumulation
(:func:`vibroscope.stream.accumulate_log` of each log in turn) is the baseline beside them::

    python benchmarks/fleet.py [--logs 4] [--messages 1000000] [--repeat 3]

Say what else ran on the machine (``uptime``): a loaded 2-core machine cannot show 2x.
"""

from __future__ import annotations

import argparse
import sys
import os
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import best  # noqa: E402


def _make_logs(d: Path, n_logs: int, n: int) -> list[str]:
    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    chs = [f"/imu.linear_acceleration.{a}" for a in "xyz"]
    out = []
    for k in range(n_logs):
        x = np.random.default_rng(k).standard_normal((3, n))
        out.append(str(write_ros2_mcap(d / f"robot{k}.mcap", Signals(x, 1000.0, chs, t0=100.0 * k))))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=4, help="logs in the job (default 4)")
    ap.add_argument("--messages", type=int, default=1_000_000, help="Imu messages per log (default 1e6: 17 min at 1 kHz)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per case, best taken (default 3)")
    ap.add_argument("--nperseg", type=int, default=4096)
    args = ap.parse_args()
    from dask.distributed import Client

    from vibroscope.fleet import analyse_fleet, local_cluster
    from vibroscope.stream import accumulate_log

    print(f"load before: {os.getloadavg()}")
    with tempfile.TemporaryDirectory() as d:
        logs = _make_logs(Path(d), args.logs, args.messages)
        size = sum(Path(p).stat().st_size for p in logs) / 1e6
        print(f"{args.logs} logs x {args.messages} Imu messages (zstd), {size:.0f} MB")
        seq = best(lambda: [accumulate_log(p, nperseg=args.nperseg) for p in logs], args.repeat)
        times = {}
        for workers in (1, 2):
            with local_cluster(workers) as lc, Client(lc) as c:
                analyse_fleet(logs[:1], client=c, nperseg=args.nperseg)  # warm the workers (imports)
                times[workers] = best(lambda: analyse_fleet(logs, client=c, nperseg=args.nperseg), args.repeat)
        msgs = args.logs * args.messages
        print(f"{'case':<34} {'best s':>8} {'M msg/s':>8} {'ratio':>7}")
        print(f"{'in-process, one log after another':<34} {seq:>8.3f} {msgs / seq / 1e6:>8.2f} {1.0:>7.2f}")
        for w in (1, 2):
            print(f"{f'dask LocalCluster, {w} worker(s)':<34} {times[w]:>8.3f} {msgs / times[w] / 1e6:>8.2f} "
                  f"{seq / times[w]:>7.2f}")
        print(f"speed-up 2 workers vs 1: {times[1] / times[2]:.2f}x  (load after: {os.getloadavg()})")


if __name__ == "__main__":
    main()
