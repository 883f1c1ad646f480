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
    monkeypatch.setattr(cand, "prefix_gap", lambda run, m, prefix=None: (calls.append(m), gap(m))[1])
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
    monkeypatch.setattr(cand, "prefix_gap", lambda run, m, prefix=None: gap(m))
    spec = SimpleNamespace(n=1, starts=[np.array([v]) for v in (-13.3, -11.7, -8.6)],
                           lower=np.array([-18.6]), upper=np.array([-7.8]))
    p, g = cand.bracketed_search(None, lambda p: float(p[0]), spec, -8.6, gap(-8.6))
    assert -8.6 <= p[0] <= -7.8 and abs(p[0] + 8.2) < 0.1 and g < 0.1


def test_nothing_better_keeps_the_start(monkeypatch):
    """A start at the bottom of its valley is returned unchanged with its own gap."""
    gap = _valley(-11.7, 0.5)
    monkeypatch.setattr(cand, "prefix_gap", lambda run, m, prefix=None: gap(m) if abs(m + 11.7) > 1e-12 else 0.0)
    spec = SimpleNamespace(n=1, starts=[np.array([v]) for v in (-13.3, -11.7, -9.3)],
                           lower=np.array([-18.6]), upper=np.array([-7.8]))
    p, g = cand.bracketed_search(None, lambda p: float(p[0]), spec, -11.7, 0.0)
    assert p[0] == -11.7 and g == 0.0


def test_each_joint_form_is_refined_where_the_other_form_refined_best(monkeypatch):
    """The Jenkins and the Iwan joint are screened at four links; each form's N_LOCATIONS best
    probed links are refined. The Jenkins joint refines best at link c, where the Iwan joint
    probed fourth: the Iwan joint must be refined at c too (and win there), and nowhere else
    beyond its three; a class of one form gains nothing."""
    links = ["a", "b", "c", "d"]
    probe_gap = {("jenkins", "a"): 0.30, ("jenkins", "b"): 0.31, ("jenkins", "c"): 0.32, ("jenkins", "d"): 0.40,
                 ("iwan", "a"): 0.20, ("iwan", "b"): 0.21, ("iwan", "d"): 0.22, ("iwan", "c"): 0.25,
                 (None, "a"): 0.5, (None, "b"): 0.6, (None, "c"): 0.7, (None, "d"): 0.8}
    refined_gap = {("jenkins", "a"): 0.10, ("jenkins", "b"): 0.12, ("jenkins", "c"): 0.05,
                   ("iwan", "a"): 0.09, ("iwan", "b"): 0.11, ("iwan", "d"): 0.13, ("iwan", "c"): 0.02}

    def spec(effect, form, link):
        where = {"between": [link, "ground"]} | ({"form": form} if form else {})
        return SimpleNamespace(effect=effect, where=where, lifts_from=None, form=form, link=link,
                               variant=None)

    specs = ([spec("joint_friction", f, x) for f in ("jenkins", "iwan") for x in links]
             + [spec("cubic_stiffness", None, x) for x in links])
    refined = []
    monkeypatch.setattr(cand, "probe", lambda run, other, s: (s, np.zeros(1), probe_gap[(s.form, s.link)], None))

    def refine(run, other, item):
        s = item[0]
        refined.append((s.effect, s.form, s.link))
        return (s, item[1], refined_gap.get((s.form, s.link), item[2] / 2), None)

    monkeypatch.setattr(cand, "refine_on_either_base", refine)
    bar = SimpleNamespace(update=lambda n: None)
    out = cand.screen_nonlinear(None, specs, bar, workers=1)
    assert ("joint_friction", "iwan", "c") in refined
    assert len([r for r in refined if r[1] == "iwan"]) == cand.N_LOCATIONS + 1
    assert len([r for r in refined if r[0] == "cubic_stiffness"]) == cand.N_LOCATIONS
    assert len(refined) == len(set(refined))
    best = min(out, key=lambda r: r[2])
    assert (best[0].form, best[0].link, best[2]) == ("iwan", "c", 0.02)
    assert len(out) == len(specs)
