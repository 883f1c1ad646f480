"""What the outputs cost (issue 20, item 11): ``vibroscope analyse LOG`` with every output (rerun
recording, PNG figures) against ``--no-rrd --no-figures``, each a whole fresh process, alternated in
the same run::

    python benchmarks/analyse_outputs.py [--messages 1e6] [--repeat 3] [--log LOG]

The log is a ROS 2 Imu recording of `--messages` messages at 1 kHz (three axes: three resonances
at 12, 37 and 83 Hz under white noise, gravity on z), written with the project's writer, unless
`--log` names one. The runs alternate (analysis only, then all outputs) so that a change of the
machine's load hits both; the figure is the ratio of the medians (all outputs / analysis only),
with the medians of wall and CPU time (user + system, the worker processes included) and the load
average before and after. On a shared machine compare the ratios, not the seconds. "All outputs"
is the rerun recording, the PNG figures and the ``--json`` summary.

``--against TREE`` also runs both cases with another checkout's package first on ``PYTHONPATH``
(e.g. ``/work/main``: the code before a change), alternated with this one's, so that the two
ratios come from the same run and the same load.

``--warm`` adds each case run a second time in one process (``vibroscope.cli.main`` called twice:
the imports, numba's kernels, the matplotlib/rerun modules already loaded), median of `--repeat`
processes: the fresh-process figures beside the warm ones.

``--phases`` adds where one fresh all-outputs process spends its wall time: a time line of the
command's steps (start-up and imports, read, plan, identification, the summary JSON, the rerun
recording, the wait for the figures' workers), each with its wall and this process's CPU time
(all its threads; the workers' CPU is given at the end), from wrappers put around those steps. The
wrappers import the steps' modules (the numerics) before the command starts, so the drawing server
(:mod:`vibroscope.viewers.drawing_server`) starts ~0.7 s later than in a plain run: read the
medians, not this time line, for the command's wall time. The CPU time of the workers forked from
the drawing server counts because the command waits for the server at its end.

Each process loads vibroscope's compiled bytecode, as an installed package does: where the
environment forbids writing it (``PYTHONDONTWRITEBYTECODE``, set on the project's shared machine,
which makes every process compile the package's ~70 modules it imports from source, ~0.3 s of
CPU), the runs write and read it under a temporary ``PYTHONPYCACHEPREFIX`` instead, after one
untimed run of each tree; ``--as-is`` keeps the environment as it is.

The target of issue 20, item 11 is a whole ``analyse`` of the 1e6-message log with all outputs in
at most 4 s wall on the 2-core machine: the line ``target`` says whether the median met it, with
the load average (on a loaded machine the wall time of a process is that of its CPU time shared
with the others; the ratio of CPU times then says more than the seconds).

``--csd`` adds what a command-line user sees of the cross-spectral engine: ``csd_matrix`` of 10
channels × 2e6 samples (nperseg 4096, the README's case) as the first call of a fresh process
(numba's compiled kernels loaded from its cache, the threads started) and as the second call of
that process (warm), median over `--repeat` processes, against one pairwise ``scipy.signal.csd``
pass over the same data in the same run.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def write_log(path: Path, n: int, fs: float = 1000.0) -> Path:
    """A ROS 2 Imu MCAP of `n` messages at `fs` Hz: three modes (12, 37, 83 Hz, Q 40) mixed onto x, y,
    z, plus 0.02 m/s² noise and gravity (9.80665 m/s²) on z."""
    import numpy as np
    import scipy.signal as ss

    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    rng = np.random.default_rng(0)
    modes = []
    for f in (12.0, 37.0, 83.0):
        b, a = ss.iirpeak(f, 40, fs)
        modes.append(ss.lfilter(b, a, rng.standard_normal(n)))
    mix = np.array([[1.0, 0.5, 0.3], [0.6, -1.0, 0.4], [-0.8, 0.3, 1.0]])
    x = mix @ np.array(modes) + 0.02 * rng.standard_normal((3, n))
    x[2] += 9.80665
    return write_ros2_mcap(path, Signals(data=x, fs=fs, channels=[f"/imu.linear_acceleration.{c}" for c in "xyz"],
                                         units=["m/s^2"] * 3,
                                         t0=1.7e9), frame_id="imu_link")


def _run(argv: list[str], cwd: str, tree: str | None = None) -> tuple[float, float]:
    """(wall s, CPU s of the process and its children) of one run of `argv` (with `tree` first on
    ``PYTHONPATH`` when given)."""
    env = None
    if tree:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (tree, os.environ.get("PYTHONPATH")) if p))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(argv, check=True, capture_output=True, cwd=cwd, env=env)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


_WARM = """
import sys, time
import vibroscope.cli
times = []
for k in range(2):
    argv = [a.replace("{k}", str(k)) for a in sys.argv[1:]]
    t = time.perf_counter()
    assert vibroscope.cli.main(argv) == 0
    times.append(time.perf_counter() - t)
print(*times, file=sys.stderr)
"""


def warm_runs(argv: list[str], cwd: str, repeat: int) -> tuple[float, float]:
    """Medians over `repeat` processes of (first, second) wall s of ``vibroscope ARGV`` run twice in one
    process (the outputs of the second run under other names: ``--out`` gets a ``warm<k>`` folder)."""
    firsts, seconds = [], []
    for _ in range(repeat):
        a = list(argv)
        a[a.index("--out") + 1] = os.path.join(a[a.index("--out") + 1], "warm{k}")
        err = subprocess.run([sys.executable, "-c", _WARM, *a], check=True, capture_output=True, cwd=cwd,
                             text=True).stderr.split()
        firsts.append(float(err[-2]))
        seconds.append(float(err[-1]))
    return statistics.median(firsts), statistics.median(seconds)


_PHASES = r"""
import functools, importlib, resource, sys, time
T0 = time.perf_counter()
STEPS = [("vibroscope.viewers.drawing_server", "start", "drawing server started"),
         ("vibroscope.commands.analyse", "analyse_log", "read + analysis"),
         ("vibroscope.io", "read_mcap", "  read the log"),
         ("vibroscope.pipeline", "_plan", "  plan (band, decimation)"),
         ("vibroscope.pipeline", "_identify", "  spectra + identification"),
         ("vibroscope.commands.analyse", "write_outputs", "outputs"),
         ("vibroscope.pipeline", "summary_dict", "  summary JSON"),
         ("vibroscope.viewers.figures", "PendingFigures.__init__", "  figure workers forked"),
         ("vibroscope.viewers.rerun_view", "log_analysis", "  rerun recording"),
         ("vibroscope.commands._writers", "_in_worker", "  rerun recording (a server worker)"),
         ("vibroscope.viewers.figures", "PendingFigures.wait", "  waiting for the figures")]


def wrap(mod, attr, label):
    obj = importlib.import_module(mod)
    *path, name = attr.split(".")
    for p in path:
        obj = getattr(obj, p)
    f = getattr(obj, name)

    @functools.wraps(f)
    def timed(*a, **k):
        t, c = time.perf_counter(), time.process_time()
        try:
            return f(*a, **k)
        finally:
            print(f"phase {label:30s} start {t - T0:6.2f} s  wall {time.perf_counter() - t:6.2f} s  "
                  f"cpu {time.process_time() - c:6.2f} s", file=sys.stderr)
    setattr(obj, name, timed)


import vibroscope.cli
print(f"phase {'import vibroscope.cli':30s} start {0:6.2f} s  wall {time.perf_counter() - T0:6.2f} s", file=sys.stderr)
for m, a, label in STEPS:
    wrap(m, a, label)
print(f"phase {'(imports of the steps above)':30s} end   {time.perf_counter() - T0:6.2f} s", file=sys.stderr)
status = vibroscope.cli.main(sys.argv[1:])
me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
print(f"phase {'end':30s} at    {time.perf_counter() - T0:6.2f} s  cpu this process "
      f"{me.ru_utime + me.ru_stime:.2f} s, worker processes {kids.ru_utime + kids.ru_stime:.2f} s", file=sys.stderr)
"""


def phases(argv: list[str], cwd: str) -> None:
    """Print the time line of one fresh ``vibroscope ARGV`` process (see the module docstring)."""
    t = time.perf_counter()
    err = subprocess.run([sys.executable, "-c", _PHASES, *argv], check=True, capture_output=True, cwd=cwd,
                         text=True).stderr
    wall = time.perf_counter() - t
    print(f"case=analyse_phases  one fresh all-outputs process, wall {wall:.2f} s (with the wrappers), "
          f"load_avg={os.getloadavg()[0]:.1f}")
    for line in err.splitlines():
        if line.startswith("phase "):
            print("  " + line[6:])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=float, default=1e6, help="messages of the generated Imu log (default 1e6)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each case, alternated (default 3)")
    ap.add_argument("--log", type=Path, help="analyse this log instead of a generated one")
    ap.add_argument("--csd", action="store_true", help="also time csd_matrix fresh (first call) and warm")
    ap.add_argument("--as-is", action="store_true",
                    help="keep PYTHONDONTWRITEBYTECODE when set (every process compiles the package from source)")
    ap.add_argument("--warm", action="store_true", help="also time each case as the second run in one process")
    ap.add_argument("--phases", action="store_true", help="also print the time line of one fresh all-outputs run")
    ap.add_argument("--against", metavar="TREE", help="also run both cases with this checkout's package "
                                                      "(e.g. /work/main), alternated, for its ratio in the same run")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        log = args.log.resolve() if args.log else write_log(Path(d) / "imu.mcap", int(args.messages))
        cli = [sys.executable, "-m", "vibroscope.cli", "analyse", str(log), "--out", d]
        cases = {"analysis only (--no-rrd --no-figures)": [*cli, "--no-rrd", "--no-figures"],
                 "all outputs (rrd + figures + json)": [*cli, "--json", "summary.json"]}
        trees = {"": None, **({f" [{args.against}]": args.against} if args.against else {})}
        if os.environ.get("PYTHONDONTWRITEBYTECODE") and not args.as_is:  # bytecode as an installed package has it
            del os.environ["PYTHONDONTWRITEBYTECODE"]
            os.environ["PYTHONPYCACHEPREFIX"] = os.path.join(d, "pycache")
            for tree in trees.values():  # untimed: compiles and writes what the runs import
                _run(cases["all outputs (rrd + figures + json)"], d, tree)
            print("# bytecode: written once under a temporary PYTHONPYCACHEPREFIX (PYTHONDONTWRITEBYTECODE was set; "
                  "--as-is to keep it)")
        res: dict[tuple, list] = {(tag, k): [] for tag in trees for k in cases}
        load0 = os.getloadavg()[0]
        for _ in range(args.repeat):
            for tag, tree in trees.items():
                for name, argv in cases.items():
                    res[tag, name].append(_run(argv, d, tree))
        load1 = os.getloadavg()[0]
        warm = {name: warm_runs(argv[3:], d, args.repeat) for name, argv in cases.items()} if args.warm else {}
        if args.phases:
            phases(cases["all outputs (rrd + figures + json)"][3:], d)
    med = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v)) for k, v in res.items()}
    size = f"{log.name}, {log.stat().st_size / 2**20:.0f} MiB" if args.log else f"Imu log of {args.messages:.0e} messages"
    for (tag, name), (w, c) in med.items():
        print(f"case=analyse_outputs{tag}  {name}  {size}  median_wall_s={w:.2f}  median_cpu_s={c:.2f}  "
              f"runs={args.repeat}")
    for tag in trees:
        (w0, c0), (w1, c1) = (med[tag, name] for name in cases)
        print(f"case=analyse_outputs{tag}  ratio all/none  wall={w1 / w0:.2f}x  cpu={c1 / c0:.2f}x  "
              f"load_avg={load0:.1f}->{load1:.1f}  cores={len(os.sched_getaffinity(0))}")
    w_all = med["", "all outputs (rrd + figures + json)"][0]
    print(f"case=analyse_outputs  target all outputs <= 4 s wall (2 cores, idle): median_wall_s={w_all:.2f}  "
          f"{'met' if w_all <= 4.0 else 'not met'}  load_avg={load0:.1f}->{load1:.1f}")
    for name, (w_fresh, w) in warm.items():
        print(f"case=analyse_outputs_warm  {name}  fresh process median_wall_s={med['', name][0]:.2f}  "
              f"second run in the process median_wall_s={w:.2f}  (fresh in that process {w_fresh:.2f})  runs={args.repeat}")
    if warm:
        (f0, w0), (f1, w1) = warm.values()
        print(f"case=analyse_outputs_warm  ratio all/none  warm={w1 / w0:.2f}x  (fresh in those processes "
              f"{f1 / f0:.2f}x)")
    if args.csd:
        csd_fresh_warm(args.repeat)


_CSD = """
import time
t = time.perf_counter()
import numpy as np
from vibroscope.spectral import csd_matrix
x = np.random.default_rng(0).standard_normal((10, 2_000_000))
t1 = time.perf_counter()
csd_matrix(x, fs=1000.0, nperseg=4096)
t2 = time.perf_counter()
csd_matrix(x, fs=1000.0, nperseg=4096)
t3 = time.perf_counter()
print(t2 - t1, t3 - t2, t1 - t)
"""


def csd_fresh_warm(repeat: int) -> None:
    """Print the fresh-process and warm ``csd_matrix`` times (10 ch × 2e6) and their ratios to one
    pairwise ``scipy.signal.csd`` pass (55 calls) timed in this process."""
    import itertools

    import numpy as np
    import scipy.signal as ss

    load0 = os.getloadavg()[0]
    runs = [tuple(map(float, subprocess.run([sys.executable, "-c", _CSD], check=True, capture_output=True,
                                             text=True).stdout.split())) for _ in range(repeat)]
    fresh, warm = statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)
    x = np.random.default_rng(0).standard_normal((10, 2_000_000))
    t = time.perf_counter()
    for i, j in itertools.combinations_with_replacement(range(10), 2):
        ss.csd(x[i], x[j], fs=1000.0, nperseg=4096)
    scipy_s = time.perf_counter() - t
    print(f"case=csd_fresh_warm  10 ch x 2e6  first call of a fresh process (numba's import and "
          f"kernel load included; numpy, vibroscope.spectral and the data not) median_s={fresh:.3f}  warm (second call) median_s={warm:.3f}  pairwise scipy {scipy_s:.2f} s  "
          f"ratio fresh={scipy_s / fresh:.1f}x warm={scipy_s / warm:.1f}x  runs={repeat}  "
          f"load_avg={load0:.1f}->{os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
