"""Start-up of the command line (issue #9, target 9): ``vibroscope --help`` and ``vibroscope info LOG``
against ``python -c pass``, each a fresh process, median of `--repeat` runs::

    python benchmarks/startup.py [--repeat 15]

Which heavy libraries these commands load is a test (tests/test_project.py): none of rerun,
matplotlib, control, dask or numba.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _median_s(argv: list[str], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15, help="runs per case (default 15)")
    args = ap.parse_args()
    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    with tempfile.TemporaryDirectory() as d:
        log = Path(d) / "x.mcap"
        x = np.random.default_rng(0).standard_normal((3, 10_000))
        write_ros2_mcap(log, Signals(data=x, fs=1000.0, channels=[f"/imu.linear_acceleration.{c}" for c in "xyz"],
                                     units=["m/s^2"] * 3))
        base = _median_s([sys.executable, "-c", "pass"], args.repeat)
        print(f"case=startup  python -c pass  median_s={base:.3f}")
        for name, argv in (("vibroscope --help", ["--help"]), ("vibroscope info LOG", ["info", str(log)])):
            t = _median_s([sys.executable, "-m", "vibroscope.cli", *argv], args.repeat)
            print(f"case=startup  {name}  median_s={t:.3f}  ratio={t / base:.1f}x  extra_s={t - base:.3f}")


if __name__ == "__main__":
    main()
