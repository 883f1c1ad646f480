"""MAC, mode pairing and the ModalModel container."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibroscope.modal import ModalModel, Mode, mac, mac_matrix, match_modes, mpc, normalize_shapes


def test_mac_identical_orthogonal_scaled():
    rng = np.random.default_rng(0)
    a = rng.standard_normal(6) + 1j * rng.standard_normal(6)
    assert mac(a, a)[0, 0] == pytest.approx(1.0)
    # complex scale invariance
    assert mac(a, (-2.5 + 4j) * a)[0, 0] == pytest.approx(1.0)
    # orthogonal (Hermitian inner product zero)
    b = rng.standard_normal(6) + 1j * rng.standard_normal(6)
    b_orth = b - (a.conj() @ b) / (a.conj() @ a) * a
    assert mac(a, b_orth)[0, 0] == pytest.approx(0.0, abs=1e-15)
    assert mac([1, 0, 0], [0, 1, 0])[0, 0] == 0.0


def test_mac_matrix_shape_and_values():
    A = np.eye(4)[:3]
    B = np.eye(4)[[2, 0]]
    M = mac_matrix(A, B)
    assert M.shape == (3, 2)
    assert np.array_equal(M, [[0, 1], [0, 0], [1, 0]])
    # auto-MAC is symmetric with a unit diagonal
    rng = np.random.default_rng(1)
    S = rng.standard_normal((5, 8))
    auto = mac(S)
    assert np.allclose(auto, auto.T) and np.allclose(np.diag(auto), 1)
    # known value: MAC([1,1],[1,0]) = 1/2
    assert mac([1, 1], [1, 0])[0, 0] == pytest.approx(0.5)


def test_mac_errors_and_zero():
    with pytest.raises(ValueError, match="points"):
        mac(np.ones(3), np.ones(4))
    assert np.isnan(mac(np.zeros(3), np.ones(3))[0, 0])


def test_match_modes_permuted():
    rng = np.random.default_rng(2)
    shapes = np.linalg.qr(rng.standard_normal((5, 5)))[0].T  # orthonormal rows
    f = np.array([3.0, 7.0, 12.0, 20.0, 31.0])
    perm = [3, 0, 4, 1]  # a subset, shuffled
    est = ModalModel(natural_frequencies=f[perm] * 1.01, damping_ratios=np.full(4, 0.01), shapes=shapes[perm] * 2j,
                     points=list("abcde"), method="test")
    m = match_modes(est, (f, shapes))
    assert m.pairs.tolist() == [[1, 0], [3, 1], [0, 3], [2, 4]]
    assert np.allclose(m.frequency_errors, 0.01)
    assert np.allclose(m.mac, 1)
    assert len(match_modes(est, (f, shapes), max_frequency_error=0.005).pairs) == 0


def test_normalize_and_mpc():
    s = normalize_shapes([[0.5j, -2j, 1j]])
    assert np.allclose(s, [[-0.25, 1, -0.5]])
    assert mpc(s)[0] == pytest.approx(1.0)
    assert mpc([1, 1j])[0] == pytest.approx(0.0)


def test_modal_model_container():
    m = ModalModel(natural_frequencies=[2.0, 5.0], damping_ratios=[0.01, np.nan], shapes=[[1, 0.5j], [-0.3, 1]],
                   points=["/a.x", "/b.x"], method="fdd", extra={"mpc": np.ones(2)})
    assert len(m) == 2
    modes = list(m)
    assert all(isinstance(x, Mode) for x in modes)
    assert modes[1].natural_frequency == 5.0 and modes[1].index == 1 and modes[1].method == "fdd"
    assert m[-1].natural_frequency == 5.0
    d = m.to_dict()
    json.dumps(d)  # JSON-ready
    assert d["method"] == "fdd" and d["points"] == ["/a.x", "/b.x"]
    e = d["modes"][0]
    assert set(e) == {"frequency_hz", "damping_ratio", "shape", "method"}
    assert e["shape"] == {"/a.x": [1.0, 0.0], "/b.x": [0.0, 0.5]}
    assert d["modes"][1]["damping_ratio"] is None
    assert not m.shapes.flags.writeable
    with pytest.raises(ValueError):
        ModalModel(natural_frequencies=[1.0], damping_ratios=[0.1, 0.2], shapes=[[1, 2]], points=["a", "b"], method="x")
    with pytest.raises(ValueError):
        ModalModel(natural_frequencies=[1.0], damping_ratios=[0.1], shapes=[[1, 2, 3]], points=["a", "b"], method="x")
    assert "2 modes" in repr(m)


def test_import_boundaries():
    """``vibroscope.modal`` imports only spectral and signals of vibroscope, and no plotting."""
    import subprocess
    import sys

    code = (
        "import sys, vibroscope.modal; "
        "bad = [m for m in sys.modules if m.startswith(('vibroscope.io', 'vibroscope.viewers', "
        "'vibroscope.models', 'vibroscope.gap', 'matplotlib', 'rerun', 'mcap', 'dask'))]; "
        "print(bad); sys.exit(1 if bad else 0)"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_match_modes_mac_min_drops_pairs_below_it():
    ref = (np.array([10.0, 20.0]), np.eye(3)[:2])
    est = (np.array([10.1, 19.9]), np.array([[1.0, 0.0, 0.0], [0.6, 0.8, 0.0]]))  # MAC 1 and 0.64
    assert len(match_modes(est, ref).pairs) == 2
    m = match_modes(est, ref, mac_min=0.7)
    np.testing.assert_array_equal(m.pairs, [[0, 0]])
    assert m.mac[0] == pytest.approx(1.0)


def _two_dof_frf():
    from vibroscope.models import LumpedModel
    from vibroscope.spectral import FRF

    model = LumpedModel.chain([1.0, 1.0], [2e4, 2e4], [4.0, 4.0])
    f = np.arange(1, 2001) * 0.05
    return model, FRF(frequencies=f, H=model.frf(f), coherence=np.ones((2000, 2)), inputs=["u"], outputs=["a1", "a2"],
                      estimator="analytic", kind="accelerance")


def test_stabilization_is_read_only_and_prints_a_summary():
    from vibroscope.modal import lscf, lsfd

    model, h = _two_dof_frf()
    st = lscf(h, orders=range(2, 21), mac_min=0.98)
    assert st.settings["mac_min"] == 0.98 and "tol_mac" not in st.settings
    for name in ("order", "frequency", "damping", "shapes", "stable"):
        with pytest.raises(ValueError):
            getattr(st, name)[0] = 0
    text = repr(st)
    assert text.startswith("Stabilization('lscf', ") and "orders 2–20" in text and "array" not in text
    modes = st.modal_model()
    # analytic FRF: round-off (measured 7.3e-11), tolerance ~70x
    np.testing.assert_allclose(modes.natural_frequencies, model.modes().natural_frequencies, rtol=5e-9)
    res = lsfd(h, modes.natural_frequencies, modes.damping_ratios)
    text = repr(res)
    assert text.startswith("LSFDResult(2 modes, f = [13.91, 36.42] Hz") and "array" not in text


def test_singular_values_is_a_result_that_unpacks():
    from vibroscope.modal import SingularValues, singular_values
    from vibroscope.spectral import csd_matrix

    x = np.random.default_rng(4).standard_normal((3, 8192))
    G = csd_matrix(x, 100.0, nperseg=256)
    sv = singular_values(G)
    assert isinstance(sv, SingularValues) and sv.channels == G.channels and sv.settings["nperseg"] == 256
    f, S = sv
    assert len(sv) == 2 and sv[0] is f and sv[1] is S and S.shape == (129, 3)
    np.testing.assert_allclose(S.sum(axis=1), np.real(np.trace(G.G, axis1=1, axis2=2)), rtol=1e-10)
    with pytest.raises(ValueError):
        S[0, 0] = 1.0
    assert repr(sv) == "SingularValues(3 of 3 channels ['0', '1', '2'], 129 lines, 0–50 Hz)"


def test_resonance_peaks_find_the_vertex_between_lines():
    """The parabolic refinement is exact for a parabola (in dB) whose vertex lies between lines."""
    from vibroscope.modal.compare import resonance_peaks

    f = np.arange(0.0, 50.0, 0.5)
    db = np.maximum(-40.0, -((f - 20.3) ** 2))
    assert resonance_peaks(f, db, prominence=3.0) == pytest.approx([20.3], abs=1e-9)
