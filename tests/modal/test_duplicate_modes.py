"""One physical mode is never reported as several (sweep report, problem 2).

At a coarse resolution (the demo's 18.4 Hz mode, ζ ≈ 1 %, at Δf = 0.49 Hz) LSCF splits the
mode into two poles of the same model order that bracket it; each pair member forms a stable
cluster beside the mode's own cluster, and three identical shapes less than two lines apart
were reported. The selection now keeps one of candidates within two lines whose shapes agree
(MAC ≥ 0.9), and with gaps the damping refinement of ``analyse_signals`` still doubles
``nperseg`` while 5 gap-free segments fit. Truth: the demo model's modes (18.39, 41.92,
60.38 Hz)."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.modal import ModalModel, mac
from vibroscope.modal.selection import select_modes
from vibroscope.models import demo_model
from vibroscope.models.excitation import band_limited_random
from vibroscope.models.simulate import simulate
from vibroscope.pipeline import analyse_signals
from vibroscope.signals import Signals

MODEL = demo_model()
TRUE_HZ = MODEL.modes().natural_frequencies  # 18.39, 41.92, 60.38 Hz
FORCE = MODEL.input_channels()[0]


@pytest.fixture(scope="module")
def demo_signals() -> Signals:
    """The demo's record (``vibroscope demo`` with ``--duration 20``): 20 s at 1 kHz, force first."""
    fs, n = 1000.0, 20000
    u = band_limited_random(fs, n, fmin=2.0, fmax=0.3 * fs, rms=20.0, seed=1)
    return simulate(MODEL, u, fs, t0=1.7e9, noise=0.02, seed=2)


def _with_nan(sig: Signals, rows: slice, start: int, stop: int) -> Signals:
    data = np.array(sig.data)
    data[rows, start:stop] = np.nan
    return Signals(data=data, fs=sig.fs, channels=sig.channels, units=sig.units, t0=sig.t0, meta=sig.meta)


def _assert_true_modes(mm, rel=0.005):
    assert len(mm) == 3, mm.natural_frequencies
    assert mm.natural_frequencies == pytest.approx(TRUE_HZ, rel=rel)


# -- the rule -------------------------------------------------------------------------------------

SHAPE = np.array([0.3, 0.7, 1.0], complex)


def _split_candidates(orders=True, sizes=(48, 30, 48)):
    """What LSCF gave on the demo at Δf = 0.488 Hz: the mode's cluster (orders 16-45) between the
    two halves of its split (both at orders 53-100), plus a distinct mode at 41.9 Hz."""
    f = [18.056, 18.375, 18.574, 41.92]
    extra = {"cluster_size": np.array([*sizes, 86])}
    if orders:
        co = np.empty(4, object)
        co[:] = [frozenset(range(53, 101)), frozenset(range(16, 46)), frozenset(range(53, 101)),
                 frozenset(range(15, 101))]
        extra["cluster_orders"] = co
    shapes = np.array([SHAPE, SHAPE * 1.01, SHAPE, [1.0, -0.2, -0.6]], complex)
    return ModalModel(natural_frequencies=f, damping_ratios=[0.009, 0.015, 0.011, 0.023], shapes=shapes,
                      points=["a", "b", "c"], method="lscf", extra=extra)


def test_split_mode_is_one_mode_the_cluster_alone_at_its_orders():
    sel = select_modes(_split_candidates(), resolution_hz=0.4883)
    assert list(sel.modes.natural_frequencies) == [18.375, 41.92]
    assert list(sel.modes.extra["cluster_size"]) == [30, 86]  # per-mode extras follow the kept modes
    reasons = {r.natural_frequency: r.reason for r in sel.rejected}
    assert sorted(reasons) == [18.056, 18.574]
    assert reasons[18.056].startswith("duplicate of 18.375 Hz: 0.319 Hz apart")
    assert "MAC 1.000" in reasons[18.574] and "only pole at 30 model orders" in reasons[18.574]
    assert sel.criteria["duplicates"] == {"resolution_hz": 0.4883, "bins": 2.0, "mac_min": 0.9}


def test_without_a_resolution_nothing_is_merged():
    sel = select_modes(_split_candidates())
    assert len(sel.modes) == 4 and sel.rejected == () and sel.criteria["duplicates"] is None


def test_without_cluster_orders_the_largest_cluster_is_kept():
    sel = select_modes(_split_candidates(orders=False, sizes=(20, 30, 25)), resolution_hz=0.4883)
    assert list(sel.modes.natural_frequencies) == [18.375, 41.92]
    assert all("larger cluster (30 poles against" in r.reason for r in sel.rejected)


def test_close_modes_with_different_shapes_or_farther_than_two_lines_are_kept():
    # the close pair of tests/modal/test_identification.py (40 and 44.5 Hz, MAC 0.96) at Δf = 1 Hz
    # (4.5 lines apart), and a pair within one line whose shapes differ (MAC 0.5)
    a, b = np.array([1.0, 0.8]), np.array([1.0, 0.6])
    c, d = np.array([1.0, 1.0]), np.array([1.0, 0.0])
    mm = ModalModel(natural_frequencies=[10.0, 10.3, 40.0, 44.5], damping_ratios=[0.01] * 4,
                    shapes=np.array([c, d, a, b], complex), points=["x", "y"], method="lscf")

    assert mac(mm.shapes[0], mm.shapes[1])[0, 0] == pytest.approx(0.5)
    assert mac(mm.shapes[2], mm.shapes[3])[0, 0] > 0.96
    sel = select_modes(mm, resolution_hz=1.0)
    assert list(sel.modes.natural_frequencies) == [10.0, 10.3, 40.0, 44.5] and sel.rejected == ()
    # the same shapes (MAC 1) within two lines are one mode
    same = ModalModel(natural_frequencies=[40.0, 41.5], damping_ratios=[0.01] * 2, shapes=np.array([a, a], complex),
                      points=["x", "y"], method="lscf")
    assert len(select_modes(same, resolution_hz=1.0).modes) == 1
    assert len(select_modes(same, resolution_hz=0.5).modes) == 2  # 3 lines apart: resolved


def test_bad_resolution_raises():
    with pytest.raises(ValueError, match="resolution_hz"):
        select_modes(_split_candidates(), resolution_hz=0.0)


# -- end to end on the demo's record -----------------------------------------------------------------

def test_coarse_resolution_gives_three_modes(demo_signals):
    """`analyse --nperseg 2048` on the clean demo: LSCF's split of 18.4 Hz is one mode."""
    an = analyse_signals(demo_signals, input=FORCE, nperseg=2048)
    _assert_true_modes(an.modal)
    dup = [r for r in an.identification.rejected if r.reason.startswith("duplicate of")]
    assert len(dup) == 2 and all(abs(r.natural_frequency - 18.39) < 0.6 for r in dup)


@pytest.mark.parametrize("rows", [slice(1, None), slice(0, 1), slice(None)], ids=["outputs", "force", "all"])
def test_a_gap_does_not_split_a_mode(demo_signals, rows):
    """0.3 s of NaN (the sweep's nan_resp / nan_force / nan_all): the same three modes and the
    same refined resolution as the gap-free record (6 of 8 segments free of the gap at 4096)."""
    clean = analyse_signals(demo_signals, input=FORCE)
    an = analyse_signals(_with_nan(demo_signals, rows, 5000, 5300), input=FORCE)
    assert clean.settings["nperseg"] == an.settings["nperseg"] == 4096
    assert any("resolution refined for the damping: nperseg 2048 -> 4096" in w for w in an.warnings)
    _assert_true_modes(an.modal)


def test_one_infinite_sample_does_not_split_a_mode(demo_signals):
    data = np.array(demo_signals.data)
    data[1, 7000] = np.inf
    sig = Signals(data=data, fs=demo_signals.fs, channels=demo_signals.channels, units=demo_signals.units,
                  t0=demo_signals.t0)
    an = analyse_signals(sig, input=FORCE)
    assert an.settings["nperseg"] == 4096
    _assert_true_modes(an.modal)


def test_refinement_with_gaps_stops_when_fewer_than_five_clean_segments_fit(demo_signals):
    """Gaps every 4 s: 4096-sample segments no longer fit 5 times between them (2048 ones do)."""
    from vibroscope.pipeline import _clean_segments

    data = np.array(demo_signals.data)
    for k in range(3000, 20000, 4000):
        data[1:, k:k + 50] = np.nan
    sig = Signals(data=data, fs=demo_signals.fs, channels=demo_signals.channels, units=demo_signals.units,
                  t0=demo_signals.t0)
    assert _clean_segments(sig, 4096) < 5 <= _clean_segments(sig, 2048)
    an = analyse_signals(sig, input=FORCE)
    assert an.settings["nperseg"] <= 2048
    _assert_true_modes(an.modal)
