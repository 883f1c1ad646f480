"""A log larger than the memory the analysis may use (issue #9, target 3), by hand.

Writes an uncompressed ROS 2 Imu MCAP of ``--messages`` messages (default 12.5 M: 4.5 GB; a 37 Hz
resonance with ζ = 1/(2·40) = 1.25 % driven by noise, 3 axes), then runs ``vibroscope analyse LOG
--no-rrd --no-figures`` in a child process under an address-space limit (``RLIMIT_AS``, default
1 GiB, BLAS/numba threads 1): once as is (it must switch to streaming and find the mode), once with
``--max-memory 100GB`` (no streaming: it must fail for memory). Prints both outcomes, the wall time
and the peak resident memory of the streamed run.

Run: ``python examples/scale/stream_big_log.py [--dir DIR] [--messages N] [--limit-mb MB]``
(needs about 4.5 GB of free disk at the default size; the log is deleted unless ``--keep``).
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.signal as ss


def write_log(path: Path, n: int) -> Path:
    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    rng = np.random.default_rng(0)
    b, a = ss.iirpeak(37.0, 40.0, 1000.0)
    y = ss.lfilter(b, a, rng.standard_normal(n)) * 5
    x = np.vstack([y + 0.2 * rng.standard_normal(n), 0.5 * y + 0.2 * rng.standard_normal(n),
                   -y + 0.2 * rng.standard_normal(n)])
    chans = [f"/imu/wrist.linear_acceleration.{c}" for c in "xyz"]
    return write_ros2_mcap(path, Signals(data=x, fs=1000.0, channels=chans), compression="none")


def run_limited(log: Path, limit_mb: int, extra: list[str]) -> tuple[int, str, float, float]:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    lim = limit_mb * 2**20

    def limit():  # in the child, before exec
        resource.setrlimit(resource.RLIMIT_AS, (lim, lim))

    cmd = [sys.executable, "-m", "vibroscope.cli", "analyse", str(log), "--no-rrd", "--no-figures", *extra]
    t = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, preexec_fn=limit, cwd=log.parent)
    wall = time.perf_counter() - t
    rss_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return r.returncode, (r.stdout + r.stderr).strip(), wall, rss_mb


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dir", type=Path, default=None, help="where to write the log (default a temporary folder)")
    p.add_argument("--messages", type=float, default=12.5e6, help="Imu messages (default 12.5e6: 4.5 GB)")
    p.add_argument("--limit-mb", type=int, default=1024, help="address-space limit of the analysis (default 1024)")
    p.add_argument("--keep", action="store_true", help="keep the log")
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory(dir=a.dir) as d:
        log = write_log(Path(d) / "big.mcap", int(a.messages))
        print(f"{log.name}: {log.stat().st_size / 1e9:.2f} GB, {int(a.messages)} messages; "
              f"address-space limit {a.limit_mb} MiB")
        rc, out, wall, rss = run_limited(log, a.limit_mb, [])
        print(f"\n$ vibroscope analyse {log.name} --no-rrd --no-figures   (rc {rc}, {wall:.1f} s, "
              f"peak RSS {rss:.0f} MB)\n{out}")
        rc2, out2, _, _ = run_limited(log, a.limit_mb, ["--max-memory", "100GB"])
        print(f"\n$ ... --max-memory 100GB   (rc {rc2})\n{out2}")
        if a.keep:
            kept = (a.dir or Path.cwd()) / "big.mcap"
            log.replace(kept)
            print(f"kept {kept}")
    return 0 if rc == 0 and rc2 != 0 else 1


if __name__ == "__main__":
    sys.exit(main())
