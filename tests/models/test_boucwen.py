"""The Bouc-Wen hysteretic benchmark (Noël & Schoukens 2016): reproduce the published,
noise-free validation outputs from their inputs. Data: ../shared/data/boucwen (skips without)."""

import numpy as np
import pytest

from vibroscope.models.boucwen_benchmark import boucwen_benchmark_model, simulate_boucwen_benchmark


@pytest.fixture(scope="module")
def load(shared_data):
    """``load(name)``: one benchmark record as a flat float array (skips without the data)."""
    from scipy.io import loadmat

    data = shared_data / "boucwen"
    if not data.is_dir():
        pytest.skip(f"Bouc-Wen benchmark data not found at {data}")
    return lambda name: np.asarray(loadmat(data / f"{name}.mat")[name], dtype=float).ravel()


def test_linear_part_matches_table2():
    # Table 2: 35.59 Hz, 1.12 % with the small-motion stiffness k_L + alpha
    m = boucwen_benchmark_model()
    assert m.K[0, 0] == 5e4 and m.C[0, 0] == 10.0 and m.M[0, 0] == 2.0
    fn = np.sqrt((m.K[0, 0] + 5e4) / 2.0) / (2 * np.pi)
    assert fn == pytest.approx(35.59, abs=0.005)


def test_multisine_validation_output(load):
    """One steady-state period (8192 samples at 750 Hz): simulate 2 periods at 15 kHz and
    compare the last; published accuracy target 1e-6 m RMS (output RMS ~6.7e-4 m)."""
    u, y = load("uval_multisine"), load("yval_multisine")
    ys = simulate_boucwen_benchmark(u, fs=750.0, periodic=True, n_periods=2)
    err = np.sqrt(np.mean((ys - y) ** 2))
    print(f"Bouc-Wen multisine RMS error {err:.3e} m (output RMS {np.sqrt(np.mean(y**2)):.3e} m)")
    assert err < 1e-6


@pytest.mark.slow
def test_sinesweep_validation_output(load):
    """The sine sweep (153 000 samples, from rest): 3.06 million integration steps."""
    u, y = load("uval_sinesweep"), load("yval_sinesweep")
    ys = simulate_boucwen_benchmark(u, fs=750.0)
    err = np.sqrt(np.mean((ys - y) ** 2))
    print(f"Bouc-Wen sine-sweep RMS error {err:.3e} m (output RMS {np.sqrt(np.mean(y**2)):.3e} m)")
    assert err < 1e-5
