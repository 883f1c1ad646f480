"""Every benchmark of vibroscope in one run, one after the other (the README's table comes from one).

``python benchmarks/all.py [--log FILE] [--quick]`` runs, each in a fresh process so that one case's
threads, caches and memory do not leak into the next:

========================  =====================================================================
``run.py``                CSD engine at 2e6 (vs pairwise scipy, one thread, float32, ``np.sum``,
                          memory), MCAP read, nonlinear simulation
``run.py --samples 1e7``  the CSD cases at 1e7 samples
``mcap_ingest.py``        MCAP ingestion: Imu zstd/lz4 (mixed frame ids too), JSON, protobuf
``fleet.py``              Dask fleet: 1 vs 2 worker processes on a multi-file job (4 logs of 1e6
                          and of 3e5 messages)
``rerun_log.py``          rerun: 1e7 samples + 1000 spectra, envelope, live view
``modal_threads.py``      SSI-COV on LUMO, one BLAS thread vs default, idle and loaded
``startup.py``            CLI start-up against ``python -c pass``
``analyse_outputs.py``    ``analyse`` of a 1e6-message Imu log with every output (rerun recording,
                          figures) against ``--no-rrd --no-figures``, whole processes, alternated;
                          the same as the second run of one process (warm); one fresh run's
                          time line (``--warm --phases``)
``scaling.py``            time and memory vs length and channels (``docs/bench/scaling.png``)
========================  =====================================================================

Each script prints its own medians/best times and ratios against a baseline measured in the same
run; this driver adds the machine load before and after each (``os.getloadavg``).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _cases(quick: bool) -> list[list[str]]:
    if quick:
        return [["run.py", "--quick"], ["startup.py", "--repeat", "3"]]
    return [
        ["run.py"],
        ["run.py", "--only-csd", "--samples", "1e7"],
        ["mcap_ingest.py", "--msgs", "1e6", "--mixed"],
        ["fleet.py"],
        ["fleet.py", "--messages", "300000"],
        ["rerun_log.py"],
        ["modal_threads.py"],
        ["startup.py"],
        ["analyse_outputs.py", "--warm", "--phases"],
        ["scaling.py"],
    ]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--log", type=Path, help="also write everything printed to this file")
    p.add_argument("--quick", action="store_true", help="two small cases only (a smoke run)")
    a = p.parse_args(argv)
    out = [f"# vibroscope benchmarks, {time.strftime('%Y-%m-%d %H:%M:%S')}, {os.cpu_count()} cores"]
    print(out[0], flush=True)
    rc = 0
    for case in _cases(a.quick):
        t = time.perf_counter()
        before = os.getloadavg()[0]
        r = subprocess.run([sys.executable, str(HERE / case[0]), *case[1:]], capture_output=True, text=True,
                           cwd=HERE.parent)
        head = (f"\n## {' '.join(case)}  (rc {r.returncode}, {time.perf_counter() - t:.0f} s, load "
                f"{before:.1f} -> {os.getloadavg()[0]:.1f})")
        text = head + "\n" + r.stdout + (("\n[stderr]\n" + r.stderr[-3000:]) if r.returncode else "")
        print(text, flush=True)
        out.append(text)
        rc = rc or r.returncode
    if a.log:
        a.log.write_text("\n".join(out) + "\n")
    return rc


if __name__ == "__main__":
    sys.exit(main())
