"""Time-series outputs made ahead, while the modes are identified (issue 20, item 11): the same
integrals and the same PNG bytes as the outputs would compute, for that record only; the
pipeline's hook hands over the record the analysis returns."""

from __future__ import annotations

import multiprocessing
import sys

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import _viewers_synthetic as syn  # noqa: E402
from vibroscope.spectral.integration import velocity_and_displacement  # noqa: E402
from vibroscope.viewers import figures  # noqa: E402
from vibroscope.viewers.acquisition import plot_kinematics  # noqa: E402
from vibroscope.viewers.ahead import TimeSeriesAhead  # noqa: E402

linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the worker is forked (Linux)")


@linux
def test_ahead_gives_the_integrals_and_figures_the_outputs_would_compute(tmp_path):
    sig = syn.signals()
    acc = list(sig.channels[:2])
    with TimeSeriesAhead(figures=True, kinematics=True) as ahead:
        ahead.start(sig, acc)
        assert ahead.holds(sig, acc)
        assert not ahead.holds(syn.signals(), acc)  # another record (an equal copy): not this one's work
        assert not ahead.holds(sig, acc[:1])
        vel, disp = ahead.kinematics()
        v0, d0 = velocity_and_displacement(sig.select(acc))
        np.testing.assert_array_equal(vel.data, v0.data)
        np.testing.assert_array_equal(disp.data, d0.data)
        assert vel.channels == v0.channels and vel.units == v0.units
        drawn = ahead.drawn(sig)
        assert sorted(drawn) == ["kinematics", "signals"] and ahead.drawn(syn.signals()) == {}
        here = {"signals": figures.save_figure(figures.plot_signals(sig), tmp_path / "signals.png"),
                "kinematics": figures.save_figure(plot_kinematics(sig.select(acc), integrals=(v0, d0)),
                                                  tmp_path / "kinematics.png")}
        for name, path in here.items():
            assert drawn[name].png() == path.read_bytes(), name
    assert not multiprocessing.active_children()


@linux
def test_drawn_figures_are_written_in_the_job_order_beside_the_drawn_ones(tmp_path):
    sig = syn.signals()
    psd = syn.spectra()[0]
    with TimeSeriesAhead(figures=True, kinematics=False) as ahead:
        ahead.start(sig, [])  # no acceleration among the outputs: the signals figure only
        assert sorted(ahead.drawn(sig)) == ["signals"] and ahead.kinematics() is None
        jobs = figures.figure_jobs(tmp_path / "ahead", signals=sig, psd=psd, ahead=ahead)
        assert isinstance(jobs[0][0], figures.DrawnFigure)
        with figures.PendingFigures(jobs, workers=2) as pending:
            paths = pending.wait()
    serial = figures.summary_figures(tmp_path / "serial", signals=sig, psd=psd, workers=1)
    assert [p.name for p in paths] == [p.name for p in serial] == ["signals.png", "psd.png"]
    for a, b in zip(paths, serial):
        assert a.read_bytes() == b.read_bytes(), a.name
    assert not multiprocessing.active_children()


def test_nothing_asked_or_a_record_too_large_starts_no_worker():
    sig = syn.signals()
    for kw in (dict(figures=False, kinematics=False), dict(figures=True, kinematics=True, max_bytes=sig.data.nbytes - 1)):
        with TimeSeriesAhead(**kw) as ahead:
            ahead.start(sig, list(sig.channels))
            assert not ahead.holds(sig, list(sig.channels)) and ahead.drawn(sig) == {}
        assert not multiprocessing.active_children()


def test_the_pipeline_hands_over_the_record_it_identifies_from():
    from vibroscope.pipeline import analyse_signals

    sig = syn.signals(n=8000)
    seen = []
    an = analyse_signals(sig, nperseg=512, on_signals=lambda s, outputs: seen.append((s, outputs)))
    assert len(seen) == 1
    assert seen[0][0] is an.signals and list(seen[0][1]) == an.settings["outputs"]
