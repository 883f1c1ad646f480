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


def test_save_figure_draws_the_pixels_savefig_draws(tmp_path):
    """save_figure draws once on the Agg canvas (savefig draws a laid-out figure twice): the same pixels
    as savefig at the same dpi, quantised alike; the figure's own dpi is left as it was."""
    import io

    import numpy as np
    from PIL import Image

    def draw():
        fig = figures.pyplot().figure(figsize=(4.33, 2.9), layout="constrained")  # 476.3 x 319 px at 110 dpi
        axes = fig.subplots(2, 2, sharex=True, sharey="row")
        for k, ax in enumerate(axes.ravel()):
            ax.plot(np.sin(np.linspace(0, 7 + k, 400)) * 10 ** k, label=f"curve {k}")
            ax.set_title(f"panel {k}")
            ax.legend(loc="best")
        fig.suptitle("a laid-out figure")
        return fig

    fig = draw()
    buf = io.BytesIO()
    fig.savefig(buf, dpi=figures.DPI, format="png")
    buf.seek(0)
    with Image.open(buf) as im:
        ref = np.asarray(im.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT,
                                                     dither=Image.Dither.NONE).convert("RGB"))
    fig = draw()
    dpi = fig.dpi
    path = figures.save_figure(fig, tmp_path / "f.png")
    assert fig.dpi == dpi
    with Image.open(path) as im:
        got = np.asarray(im.convert("RGB"))
    assert got.shape == ref.shape and np.array_equal(got, ref)
