"""Scale-out on Dask (issue #9, target 4): :func:`vibroscope.fleet.analyse_fleet` of a multi-file job
on a ``LocalCluster`` of 2 single-threaded worker processes against 1, in the same run (cluster
start-up not timed; best of `--repeat`); the in-process sequential accumulation
(:func:`vibroscope.stream.accumulate_log` of each log in turn) is the baseline beside them::

    python benchmarks/fleet.py [--logs 4] [--messages 1000000] [--repeat 3]

Say what else ran on the machine (``uptime``): a loaded 2-core machine cannot show 2x. The 1- and
2-worker runs are alternated (both clusters up at once), and the same accumulation in 2 plain
processes against 1 (no Dask) is printed as the ceiling of any 2-worker speed-up on this machine.
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
from _timing import times as times_of  # noqa: E402


def _make_logs(d: Path, n_logs: int, n: int) -> list[str]:
    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    chs = [f"/imu.linear_acceleration.{a}" for a in "xyz"]
    out = []
    for k in range(n_logs):
        x = np.random.default_rng(k).standard_normal((3, n))
        out.append(str(write_ros2_mcap(d / f"robot{k}.mcap", Signals(data=x, fs=1000.0, channels=chs, t0=100.0 * k))))
    return out


def _acc(path: str, nperseg: int) -> None:
    from vibroscope.stream import accumulate_log

    accumulate_log(path, nperseg=nperseg)


def _process_ceiling(logs: list[str], nperseg: int, repeat: int) -> float:
    """How much two cores give this work without Dask: the logs accumulated by 2 plain worker
    processes at once against 1 (warm pools, best of `repeat`); the ceiling of any 2-worker speed-up
    on this machine (shared caches, memory bandwidth, and whatever the host shares the cores with)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context("spawn")
    t: dict[int, list[float]] = {1: [], 2: []}
    with ProcessPoolExecutor(1, mp_context=ctx) as e1, ProcessPoolExecutor(2, mp_context=ctx) as e2:
        pools = {1: e1, 2: e2}
        for w, ex in pools.items():
            list(ex.map(_acc, logs[:w], [nperseg] * w))  # imports, numba cache
        for _ in range(repeat):  # alternated, as the Dask runs
            for w, ex in pools.items():
                t[w] += times_of(lambda: list(ex.map(_acc, logs, [nperseg] * len(logs))), 1)
    return min(t[1]) / min(t[2])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=4, help="logs in the job (default 4)")
    ap.add_argument("--messages", type=int, default=1_000_000, help="Imu messages per log (default 1e6: 17 min at 1 kHz)")
    ap.add_argument("--repeat", type=int, default=5, help="runs per case, alternated, best taken (default 5)")
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
        # both clusters up at once (an idle worker costs nothing) and the timed runs alternated, so
        # that a slow spell of the shared host falls on both cases alike
        with local_cluster(1) as lc1, Client(lc1) as c1, local_cluster(2) as lc2, Client(lc2) as c2:
            clients = {1: c1, 2: c2}
            for c in clients.values():
                analyse_fleet(logs[:1], client=c, nperseg=args.nperseg)  # warm the workers (imports)
            runs = {1: [], 2: []}
            for _ in range(args.repeat):
                for w, c in clients.items():
                    runs[w] += times_of(lambda: analyse_fleet(logs, client=c, nperseg=args.nperseg), 1)
        times = {w: min(r) for w, r in runs.items()}
        ceiling = _process_ceiling(logs, args.nperseg, args.repeat)
        msgs = args.logs * args.messages
        print(f"{'case':<34} {'best s':>8} {'M msg/s':>8} {'ratio':>7}")
        print(f"{'in-process, one log after another':<34} {seq:>8.3f} {msgs / seq / 1e6:>8.2f} {1.0:>7.2f}")
        for w in (1, 2):
            print(f"{f'dask LocalCluster, {w} worker(s)':<34} {times[w]:>8.3f} {msgs / times[w] / 1e6:>8.2f} "
                  f"{seq / times[w]:>7.2f}")
        print(f"speed-up 2 workers vs 1: {times[1] / times[2]:.2f}x  (load after: {os.getloadavg()})")
        print(f"machine ceiling, the same accumulation in 2 plain processes vs 1 (no Dask): {ceiling:.2f}x; "
              f"Dask reaches {times[1] / times[2] / ceiling:.0%} of it")


if __name__ == "__main__":
    main()
