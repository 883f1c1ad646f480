"""The drawing server of ``vibroscope analyse`` (issue 20, item 11): workers forked from a process that
imported matplotlib and rerun make the same figures (byte for byte) and the same recording as
workers forked from the command itself, the command's own process never imports matplotlib or rerun,
and a script that could not be imported again by the workers keeps the old path."""

from __future__ import annotations

import json
import multiprocessing
import subprocess
import sys
import types
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import _viewers_synthetic as syn  # noqa: E402
from vibroscope.viewers import drawing_server, figures  # noqa: E402
from vibroscope.viewers.ahead import TimeSeriesAhead  # noqa: E402

linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forkserver workers (Linux)")


@pytest.fixture(scope="module")
def server():
    """The drawing server, started from this (pytest's guarded) main module."""
    mp = pytest.MonkeyPatch()
    mp.setattr(drawing_server, "main_is_importable", lambda: True)
    try:
        if not drawing_server.start():
            pytest.skip("no forkserver here")
        yield drawing_server.context()
    finally:
        drawing_server.stop()  # the other tests' commands run in this process, without a server
        mp.undo()
    assert drawing_server.context() is None


def _main(monkeypatch, **attrs) -> None:
    monkeypatch.setitem(sys.modules, "__main__", types.SimpleNamespace(__spec__=None, **attrs))


def test_only_a_main_module_known_to_be_importable_again_gets_the_server(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "__main__", types.SimpleNamespace(__spec__=types.SimpleNamespace(name="vibroscope.cli")))
    assert drawing_server.main_is_importable()  # python -m vibroscope.cli (guarded)
    monkeypatch.setitem(sys.modules, "__main__", types.SimpleNamespace(__spec__=types.SimpleNamespace(name="mytool")))
    assert not drawing_server.main_is_importable()
    _main(monkeypatch)  # python -c, an interactive session: nothing is imported again
    assert drawing_server.main_is_importable()
    script = tmp_path / "vibroscope"  # the console script pip writes
    script.write_text("import re\nimport sys\nfrom vibroscope.cli import main\nif __name__ == '__main__':\n"
                      "    sys.exit(main())\n")
    _main(monkeypatch, __file__=str(script))
    assert drawing_server.main_is_importable()
    unguarded = tmp_path / "run.py"  # would run the whole command again in every worker
    unguarded.write_text("from vibroscope.cli import main\nmain(['analyse', 'a.mcap'])\n")
    _main(monkeypatch, __file__=str(unguarded))
    assert not drawing_server.main_is_importable()
    _main(monkeypatch, __file__=str(tmp_path / "missing.py"))
    assert not drawing_server.main_is_importable()


@linux
def test_the_preload_keeps_a_process_exit_status_outside_the_server():
    """The preload ends the server with ``os._exit(0)`` at exit; imported anywhere else (the
    docstring test imports every module into the pytest process) that replaced the process's
    exit status, and a failing CI run exited 0. Outside the server the status stands; inside
    (the import called from ``multiprocessing.forkserver.main``, rebuilt here) the fast exit is
    registered."""
    plain = "import sys, vibroscope.viewers.drawing_preload; sys.exit(3)"
    served = ("import os, sys, multiprocessing\n"
              "path = os.path.join(os.path.dirname(multiprocessing.__file__), 'forkserver.py')\n"
              "exec(compile('def main():\\n    import vibroscope.viewers.drawing_preload', path, 'exec'))\n"
              "main(); sys.exit(3)\n")
    rc = [subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120).returncode
          for code in (plain, served)]
    assert rc == [3, 0]


def test_server_workers_draw_the_figures_drawn_here(tmp_path, server):
    psd, csd, frf, sv = syn.spectra()
    kw = dict(signals=syn.signals(), psd=psd, frf=frf, modal=syn.modal(), sv=sv, coords=syn.coords(),
              true_modes=syn.modal())
    serial = figures.summary_figures(tmp_path / "serial", workers=1, **kw)
    with figures.PendingFigures(figures.figure_jobs(tmp_path / "server", **kw), server=server) as pending:
        paths = figures.in_figure_order(pending.wait())
    assert [p.name for p in paths] == [p.name for p in serial] and len(paths) >= 5
    for a, b in zip(paths, serial):
        assert a.read_bytes() == b.read_bytes(), a.name
    assert not multiprocessing.active_children()


@linux
def test_server_ahead_gives_the_integrals_and_the_kinematics_figure(tmp_path, server):
    from vibroscope.spectral.integration import velocity_and_displacement
    from vibroscope.viewers.acquisition import plot_kinematics

    sig = syn.signals()
    acc = list(sig.channels[:2])
    with TimeSeriesAhead(figures=True, kinematics=True, server=server) as ahead:
        ahead.start(sig, acc)
        assert ahead.holds(sig, acc)
        vel, disp = ahead.kinematics()
        v0, d0 = velocity_and_displacement(sig.select(acc))
        np.testing.assert_array_equal(vel.data, v0.data)
        np.testing.assert_array_equal(disp.data, d0.data)
        drawn = ahead.drawn(sig)
        assert sorted(drawn) == ["kinematics"]  # signals.png is left to the figure pool
        here = figures.save_figure(plot_kinematics(sig.select(acc), integrals=(v0, d0)), tmp_path / "k.png")
        assert drawn["kinematics"].png() == here.read_bytes()
    assert not multiprocessing.active_children()


def _log(path: Path) -> Path:
    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    rng = np.random.default_rng(3)
    n, fs = 12_000, 200.0
    t = np.arange(n) / fs
    x = np.array([np.sin(2 * np.pi * 7.0 * t) * a for a in (1.0, 0.6, -0.8)]) + 0.05 * rng.standard_normal((3, n))
    x[2] += 9.80665
    return write_ros2_mcap(path, Signals(data=x, fs=fs, channels=[f"/imu.linear_acceleration.{c}" for c in "xyz"],
                                         units=["m/s^2"] * 3, t0=1.7e9), frame_id="imu")


_RUN = """
import sys, json
import vibroscope.cli
from vibroscope.viewers import drawing_server
start, started = drawing_server.start, []
drawing_server.start = lambda: sys.argv[1] == "server" and (started.append(start()) or started[-1])
status = vibroscope.cli.main(sys.argv[2:])
print(json.dumps({"status": status, "server": started == [True] and drawing_server.context() is None,
                  "matplotlib": "matplotlib" in sys.modules, "rerun": "rerun" in sys.modules}))
"""


@linux
def test_the_command_with_a_drawing_server_writes_what_it_wrote_without_one(tmp_path):
    from vibroscope.viewers.rerun_read import read_rrd

    log = _log(tmp_path / "imu.mcap")
    runs = {}
    for mode in ("server", "no-server"):
        out = tmp_path / mode
        p = subprocess.run([sys.executable, "-c", _RUN, mode, "analyse", str(log), "--out", str(out)],
                           capture_output=True, text=True, check=True)
        runs[mode] = json.loads(p.stdout.strip().splitlines()[-1])
        assert runs[mode]["status"] == 0
    # with the server, this process imported neither matplotlib nor rerun; without it, both
    assert runs["server"] == {"status": 0, "server": True, "matplotlib": False, "rerun": False}
    assert runs["no-server"] == {"status": 0, "server": False, "matplotlib": True, "rerun": True}
    a, b = (tmp_path / m / "imu_analyse_figures" for m in ("server", "no-server"))
    names = sorted(p.name for p in a.glob("*.png"))
    assert names == sorted(p.name for p in b.glob("*.png")) and "kinematics.png" in names and "signals.png" in names
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    ra, rb = (read_rrd(tmp_path / m / "imu_analyse.rrd") for m in ("server", "no-server"))
    assert sorted(ra) == sorted(rb) and "/signals" in " ".join(ra)
    for entity in ra:
        if entity == "/__properties":  # the recording's start time
            continue
        for col, value in ra[entity].items():
            np.testing.assert_array_equal(np.asarray(value), np.asarray(rb[entity][col]), err_msg=f"{entity} {col}")
