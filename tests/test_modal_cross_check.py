"""``vibroscope modal``'s polyMAX cross-check pairs SSI-COV and polyMAX modes one to one (issue 20 item 9).

On LUMO, SSI-COV reports 39.81 Hz (a one-node y shape) and 41.03 Hz (the y third bending mode)
where polyMAX reports one mode, 41.108 Hz; the cross-check paired both SSI-COV modes with it
(nearest in frequency, whether taken or not), as if polyMAX confirmed both. The oracle here: the
three mode shapes of a lumped 3-DOF chain (orthogonal in the mass metric, so distinct by MAC), set
at those frequencies, with polyMAX holding two of them: each polyMAX mode is paired once, with the
SSI-COV mode nearest in frequency, and the third SSI-COV mode is reported as not seen by polyMAX.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from vibroscope.commands.modal import CROSS_CHECK_MAX_DF, cross_check_text
from vibroscope.modal import ModalModel, mac
from vibroscope.models import LumpedModel

POINTS = ("a", "b", "c")


@pytest.fixture(scope="module")
def shapes():
    """The three mode shapes of a 3-DOF chain (rows), pairwise MAC < 0.5."""
    s = LumpedModel.chain([1.0, 1.0, 1.0], [1e4, 1e4, 1e4], [1.0, 1.0, 1.0]).modes().shapes
    s = np.asarray(s)[:3]
    M = mac(s, s)
    assert np.all(M[~np.eye(3, dtype=bool)] < 0.5)
    return s


def model(f, z, s, points=POINTS) -> ModalModel:
    return ModalModel(natural_frequencies=f, damping_ratios=z, shapes=s, points=points, method="x")


def pairs(text: str) -> dict:
    """``{ssi frequency: polyMAX frequency or None}`` from the cross-check line."""
    rows = text.split("SSI-COV/polyMAX: ")[1].split("; ")
    out = {}
    for r in rows:
        m = re.match(r"([\d.]+)/([\d.]+|—) Hz", r)
        out[float(m.group(1))] = None if m.group(2) == "—" else float(m.group(2))
    return out


def test_one_polymax_mode_confirms_one_ssi_mode(shapes):
    """39.81 Hz (shape 1) and 41.03 Hz (shape 2) beside the single polyMAX 41.108 Hz (shape 2):
    41.108 is paired with 41.03 only; 39.81 has no polyMAX mode (the old code paired both)."""
    ssi = model([39.807, 41.034, 42.556], [0.012, 0.004, 0.018], shapes)
    pm = model([41.108, 42.418], [0.014, 0.016], shapes[1:])
    p = pairs(cross_check_text(ssi, pm))
    assert p == {39.807: None, 41.034: 41.108, 42.556: 42.418}
    taken = [v for v in p.values() if v is not None]
    assert len(taken) == len(set(taken))
    assert cross_check_text(ssi, pm).count("MAC 1.00") == 2


def test_pairing_is_by_frequency_the_mac_shown(shapes):
    """A polyMAX mode 0.24 % above an SSI-COV mode of another shape and 2.9 % above one of its own
    shape goes with the nearer in frequency (polyMAX's shapes of close modes are the less certain);
    the line shows the MAC of the pair, 0."""
    ssi = model([39.9, 41.0], [0.01, 0.01], shapes[[1, 0]])
    pm = model([41.1], [0.01], shapes[[1]])
    text = cross_check_text(ssi, pm)
    assert pairs(text) == {39.9: None, 41.0: 41.1}
    assert "MAC 0.00" in text


def test_pairing_by_frequency_when_points_differ(shapes):
    """Shapes on other points (no MAC): one to one by frequency, and no pair farther than
    CROSS_CHECK_MAX_DF."""
    ssi = model([39.807, 41.034, 60.0], [0.01] * 3, shapes)
    pm = model([41.108, 60.0 * (1 + 2 * CROSS_CHECK_MAX_DF)], [0.01] * 2, shapes[:2], points=("a", "b", "d"))
    text = cross_check_text(ssi, pm)
    assert pairs(text) == {39.807: None, 41.034: 41.108, 60.0: None}
    assert "MAC" not in text


def test_no_polymax_mode():
    ssi = model([5.0], [0.01], [[1.0, 0.5, 0.2]])
    pm = model([], [], np.zeros((0, 3)))
    assert pairs(cross_check_text(ssi, pm)) == {5.0: None}
