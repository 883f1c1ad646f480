"""Figures drawn in worker processes (issue 20, item 11): the same files, byte for byte, as drawn in
this process; in the documented order; a job's error reaches the caller and no worker is left."""

from __future__ import annotations

import multiprocessing

import matplotlib

matplotlib.use("Agg")
import pytest  # noqa: E402

import _viewers_synthetic as syn  # noqa: E402
from vibroscope.viewers import figures  # noqa: E402


@pytest.fixture(scope="module")
def results():
    psd, csd, frf, sv = syn.spectra()
    return {"signals": syn.signals(), "psd": psd, "frf": frf, "sv": sv, "modal": syn.modal()}


def _write(out, results, workers):
    return figures.summary_figures(out, signals=results["signals"], psd=results["psd"], frf=results["frf"],
                                   modal=results["modal"], sv=results["sv"], coords=syn.coords(),
                                   true_modes=results["modal"], workers=workers)


def test_figures_drawn_in_workers_are_those_drawn_here(tmp_path, results):
    serial = _write(tmp_path / "serial", results, workers=1)
    parallel = _write(tmp_path / "parallel", results, workers=2)
    assert [p.name for p in parallel] == [p.name for p in serial] == [
        "signals.png", "psd.png", "frf.png", "modes.png", "singular_values.png"]
    for a, b in zip(serial, parallel):
        assert a.read_bytes() == b.read_bytes(), a.name
    assert not multiprocessing.active_children()


def _boom():
    raise RuntimeError("no figure here")


def test_a_failing_figure_raises_and_leaves_no_worker(tmp_path, results):
    jobs = figures.figure_jobs(tmp_path, psd=results["psd"]) + [(_boom, tmp_path / "boom.png")]
    with pytest.raises(RuntimeError, match="no figure here"):
        with figures.PendingFigures(jobs, workers=2) as pending:
            pending.wait()
    assert not multiprocessing.active_children()
    with figures.PendingFigures(jobs, workers=2):  # left without waiting (an error elsewhere): stopped
        pass
    assert not multiprocessing.active_children()
    with pytest.raises(RuntimeError, match="no figure here"):  # in this process, the same error
        figures.PendingFigures(jobs, workers=1).wait()


def test_workers_end_although_the_parent_holds_sigterm(tmp_path):
    """A parent whose SIGTERM handler only records the signal (a library's graceful shutdown, the
    held signals of the output commit) forks workers with that handler: Pool.terminate must still
    end them (run in a subprocess, so a regression fails on the timeout instead of hanging)."""
    import subprocess
    import sys

    code = (
        "import signal, sys\n"
        "got = []\n"
        "signal.signal(signal.SIGTERM, lambda s, f: got.append(s))\n"
        "import matplotlib; matplotlib.use('Agg')\n"
        "from vibroscope.viewers import figures\n"
        "import matplotlib.pyplot as plt\n"
        "def draw():\n"
        "    fig, ax = plt.subplots(); ax.plot([0, 1]); return fig\n"
        f"out = {str(tmp_path)!r}\n"
        "for k in range(3):\n"
        "    jobs = [(draw, f'{out}/a{k}.png'), (draw, f'{out}/b{k}.png')]\n"
        "    print(len(figures.PendingFigures(jobs, workers=2).wait()))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["2", "2", "2"]
