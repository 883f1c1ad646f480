"""The analysis plan and the one result type (issue 22 item 4).

:func:`vibroscope.pipeline.analyse_signals` chooses its settings once -- rate, decimation, band,
input period, segment length, method -- into a frozen :class:`~vibroscope.pipeline.AnalysisPlan`
that the report prints and the summary writes under ``plan``; then one pass executes it. A whole
read and a streamed one (:func:`vibroscope.stream.analyse_stream`) return the same type,
:class:`~vibroscope.pipeline.Analysis`, with one report and one summary function.

The oracle for the plan is the shaker of ``test_analysis_decimation.py``: a multisine of 8192
samples at 400 Hz in the 2–15 Hz band, whose decimation must divide the period (factor 8 → 50 Hz,
1024 samples a period); for the result type, the demo structure's known modes.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vibroscope.commands.analyse import report_text, stream_report_text, stream_summary
from vibroscope.models import LumpedModel
from vibroscope.models.excitation import multisine
from vibroscope.models.simulate import simulate
from vibroscope.pipeline import Analysis, AnalysisPlan, analyse_signals, summary_dict

FS = 400.0
PERIOD = 8192
MODEL = LumpedModel.chain([1.0, 0.5, 0.08], [2610.0, 1528.0, 135.0], [2.0, 1.0, 0.1], input_dof=0,
                          name="shaker 3-DOF")
INPUT = MODEL.input_channels()[0]


@pytest.fixture(scope="module")
def shaker_analysis():
    one, _ = multisine(FS, PERIOD, fmin=2.0, fmax=15.0, seed=1)
    sig = simulate(MODEL, np.tile(one, 8), FS, noise=0.02, seed=2)
    return analyse_signals(sig, input=INPUT)


def test_plan_states_rate_decimation_band_period_segment_and_method(shaker_analysis):
    an = shaker_analysis
    plan = an.plan
    assert isinstance(plan, AnalysisPlan)
    # 400 Hz; the band's top near 15 Hz allows q = 10, and 8 is the largest factor <= 10 dividing 8192
    assert plan.fs_in == FS and plan.factors == (8,) and plan.fs == 50.0 == an.signals.fs
    assert plan.period == PERIOD // 8
    assert plan.method == "lscf" == an.modal.method and plan.estimator == "H1"
    assert plan.input == INPUT and plan.outputs == tuple(an.settings["outputs"])
    lo, hi = plan.band
    assert 1.5 < lo < 2.5 and 14.0 < hi <= plan.fmax  # the multisine's 2-15 Hz lines
    # what the analysis did is what was planned (a periodic input: no refinement of the segment)
    assert an.settings["nperseg"] == plan.nperseg and plan.nperseg_refined is None
    assert an.settings["band_hz"] == list(plan.band) and an.settings["fmax"] == plan.fmax
    assert an.settings["decimation"] == {"factors": [8], "fs_in": FS, "fs_out": 50.0,
                                         "reason": plan.decimation_reason}
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.nperseg = 1  # type: ignore[misc]


def test_report_and_summary_print_the_plan(shaker_analysis):
    an = shaker_analysis
    doc = summary_dict(an)
    assert doc["plan"]["factors"] == [8] and doc["plan"]["period"] == 1024 and doc["plan"]["method"] == "lscf"
    assert list(doc).index("plan") == list(doc).index("settings") + 1
    line = next(ln for ln in report_text(an).splitlines() if ln.startswith("plan: "))
    assert "400 → 50 Hz (factors [8])" in line and "input period 1024 samples" in line
    assert f"nperseg {an.plan.nperseg}" in line and "method lscf" in line


@pytest.fixture(scope="module")
def demo_log(tmp_path_factory):
    from vibroscope.commands.demo import make_demo_log

    p = tmp_path_factory.mktemp("plan") / "demo.mcap"
    model, _ = make_demo_log(p, duration=30.0)
    return p, model.modes()


def test_the_plan_records_the_damping_refinement(demo_log):
    """The one setting that follows the identified modes: with an input and the automatic segment,
    the demo's lightly damped modes double nperseg; the plan records the length used and its line
    says so. A given nperseg is never refined."""
    from vibroscope.io import read_mcap

    p, _ = demo_log
    force = "/actuator/force.wrench.force.x"
    sig = read_mcap(p, [force, *(f"/imu/m{i}.linear_acceleration.x" for i in (1, 2, 3))])
    auto = analyse_signals(sig, input=force)
    assert auto.plan.nperseg_refined == auto.settings["nperseg"] > auto.plan.nperseg
    assert f"nperseg {auto.plan.nperseg} → {auto.plan.nperseg_refined} for the damping" in auto.plan.line()
    assert summary_dict(auto)["plan"]["nperseg_refined"] == auto.settings["nperseg"]
    given = analyse_signals(sig, input=force, nperseg=auto.plan.nperseg)
    assert given.plan.nperseg_refined is None and given.settings["nperseg"] == given.plan.nperseg


def test_whole_and_streamed_analyses_are_one_result_type(demo_log):
    from vibroscope.io import read_mcap
    from vibroscope.stream import StreamAnalysis, analyse_stream

    p, truth = demo_log
    force = "/actuator/force.wrench.force.x"
    resp = [f"/imu/m{i}.linear_acceleration.x" for i in (1, 2, 3)]
    whole = analyse_signals(read_mcap(p, [force, *resp]), input=force)
    streamed = analyse_stream(p, input=force, outputs=resp)
    assert StreamAnalysis is Analysis and type(whole) is type(streamed) is Analysis
    assert not whole.streamed and whole.plan is not None and whole.spectra is None
    assert streamed.streamed and streamed.signals is None and streamed.plan is None
    for an in (whole, streamed):  # the oracle: the demo structure's three modes
        np.testing.assert_allclose(np.sort(an.modal.natural_frequencies), truth.natural_frequencies, rtol=5e-3)
        assert an.fs == 1000.0 and an.duration_s == pytest.approx(an.n_samples / 1000.0)
    assert whole.n_samples == whole.signals.n_samples and streamed.n_samples == streamed.spectra.samples
    # one summary: the same head; the streamed one without what needs the time series
    w, s = summary_dict(whole), stream_summary(streamed)
    assert s == summary_dict(streamed)
    head = ["source", "fs", "n_samples", "duration_s", "channels", "units", "input", "outputs", "warnings"]
    assert list(w)[:9] == head == list(s)[:9]
    assert "faults" in w and "plan" in w and "faults" not in s and "plan" not in s
    assert s["settings"]["streamed"] is True and "streamed" not in w["settings"]
    # one report
    assert stream_report_text is report_text
    first = report_text(streamed, source="demo").splitlines()[0]
    assert first.startswith(f"demo: {len(streamed.channels)} channels x {streamed.n_samples} samples at 1000 Hz")
    assert ", streamed; nperseg=" in first
    assert any(ln.startswith("plan: ") for ln in report_text(whole).splitlines())
