"""The screening of a one-parameter effect: the bracketed search between its probed starts."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import vibroscope.gap._candidates as cand


def _valley(x0: float, width: float):
    """A screening gap with a narrow valley at `x0` (0.02 there) on a plateau near 0.5, and a
    slope towards it from above (what a clearance fitted on the nominal base looks like)."""
    def gap(x):
        return 0.5 - 0.48 * np.exp(-(((x - x0) / width) ** 2))
    return gap


@pytest.mark.parametrize("x_true", [-12.03, -11.2, -10.4])
def test_a_narrow_valley_between_two_starts_is_found(monkeypatch, x_true):
    """The valley (a factor 1.2 wide in the clearance) lies between the starts -13.3 and -9.3;
    the best start (-11.7) fits at the plateau's edge. The search must land within the valley's
    width of its bottom, in at most BRACKET_EVALS simulations, never outside the bracket."""
    gap = _valley(x_true, 0.2)
    calls = []
    monkeypatch.setattr(cand, "prefix_gap", lambda run, m: (calls.append(m), gap(m))[1])
    spec = SimpleNamespace(n=1, starts=[np.array([v]) for v in (-13.3, -11.7, -9.3, -8.6)],
                           lower=np.array([-18.6]), upper=np.array([-7.8]))
    p, g = cand.bracketed_search(None, lambda p: float(p[0]), spec, -11.7, gap(-11.7))
    assert -13.3 <= p[0] <= -9.3
    assert abs(p[0] - x_true) < 0.1, (p, g)
    assert g < 0.1
    assert len(calls) <= cand.BRACKET_EVALS + 2


def test_the_bracket_runs_to_the_bound_beyond_the_last_start(monkeypatch):
    """The best start is the largest: the bracket runs from the start below it to the upper bound."""
    gap = _valley(-8.2, 0.15)
    monkeypatch.setattr(cand, "prefix_gap", lambda run, m: gap(m))
    spec = SimpleNamespace(n=1, starts=[np.array([v]) for v in (-13.3, -11.7, -8.6)],
                           lower=np.array([-18.6]), upper=np.array([-7.8]))
    p, g = cand.bracketed_search(None, lambda p: float(p[0]), spec, -8.6, gap(-8.6))
    assert -8.6 <= p[0] <= -7.8 and abs(p[0] + 8.2) < 0.1 and g < 0.1


def test_nothing_better_keeps_the_start(monkeypatch):
    """A start at the bottom of its valley is returned unchanged with its own gap."""
    gap = _valley(-11.7, 0.5)
    monkeypatch.setattr(cand, "prefix_gap", lambda run, m: gap(m) if abs(m + 11.7) > 1e-12 else 0.0)
    spec = SimpleNamespace(n=1, starts=[np.array([v]) for v in (-13.3, -11.7, -9.3)],
                           lower=np.array([-18.6]), upper=np.array([-7.8]))
    p, g = cand.bracketed_search(None, lambda p: float(p[0]), spec, -11.7, 0.0)
    assert p[0] == -11.7 and g == 0.0
