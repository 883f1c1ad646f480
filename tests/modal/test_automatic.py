"""Identification with no hand-set band or order, as `analyse` and `modal` run it by default, on
the close-mode 5-DOF chain (two modes 2 % apart, modal overlap ≈ 1, 2 % output noise): the
acceptance of the modal issue, against the model's exact modes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from _close_modes import FS, NPERSEG, close_modes_5dof
from vibroscope.modal import ModalModel, mac
from vibroscope.modal.automatic import modes_document
from vibroscope.modal.selection import RejectedMode, excited_band, pick_poles, response_band, select_modes
from vibroscope.models import Input
from vibroscope.models.simulate import simulate
from vibroscope.pipeline import analyse_signals

MODEL = close_modes_5dof()
TRUE = MODEL.modes()


def _assert_matches_truth(mm, *, f_tol=1e-3, z_tol=0.05, mac_min=0.995):
    """Exactly the five true modes: frequency, damping (relative) and MAC to the true shapes."""
    assert len(mm) == len(TRUE), (mm.natural_frequencies, TRUE.natural_frequencies)
    out_dofs = [MODEL.dof_index(o.dof) for o in MODEL.outputs]
    for k in range(len(TRUE)):
        j = int(np.argmin(np.abs(mm.natural_frequencies - TRUE.natural_frequencies[k])))
        assert abs(mm.natural_frequencies[j] / TRUE.natural_frequencies[k] - 1) < f_tol
        assert abs(mm.damping_ratios[j] / TRUE.damping_ratios[k] - 1) < z_tol, (k, mm.damping_ratios[j])
        assert mac(mm.shapes[j], TRUE.shapes[k, out_dofs])[0, 0] >= mac_min


@pytest.fixture(scope="module")
def ambient():
    """Independent white forces on every mass, 2048 s at 256 Hz, 2 % output noise (outputs only)."""
    amb = MODEL.replace(inputs=tuple(Input(dof=d.name, channel=f"/f/{d.name}") for d in MODEL.dofs))
    u = np.random.default_rng(1).standard_normal((MODEL.n_dofs, 2048 * int(FS)))
    return simulate(amb, u, FS, noise=0.02, seed=2).select(amb.output_channels())


@pytest.fixture(scope="module")
def forced():
    """One white force on the tip mass, 512 s at 256 Hz, 2 % output noise: force + accelerations."""
    u = np.random.default_rng(3).standard_normal(16 * NPERSEG)
    return simulate(MODEL, u, FS, noise=0.02, seed=4)


def test_ssi_default_finds_exactly_the_five_modes(ambient):
    """Output-only default (SSI-COV, band and lags from the data): all five within 0.1 %, ζ
    within 5 %, MAC ≥ 0.995, nothing spurious; the uncertainties are bootstrap ones."""
    an = analyse_signals(ambient)
    assert an.modal.method == "ssi_cov"
    _assert_matches_truth(an.modal)
    assert "bootstrap" in an.identification.settings["uncertainty"]
    assert np.all(np.isfinite(an.modal.extra["frequency_std_hz"]))
    # the frequency errors are within a few bootstrap standard deviations
    err = np.abs(an.modal.natural_frequencies - TRUE.natural_frequencies)
    assert np.all(err < 5 * an.modal.extra["frequency_std_hz"] + 1e-4 * TRUE.natural_frequencies)


def test_lscf_default_finds_exactly_the_five_modes(forced):
    """With the force: LSCF + LSFD over the excited band; the same acceptance."""
    an = analyse_signals(forced, input=MODEL.input_channels()[0])
    assert an.modal.method == "lscf"
    _assert_matches_truth(an.modal)
    assert an.identification.lsfd is not None
    err = an.identification.lsfd.error(an.frf)
    assert np.all(np.asarray(err) < 0.2)


def test_select_at_frequencies(ambient):
    """--select F1,F2: the modes at the engineer's frequencies, from the stabilization diagram."""
    an = analyse_signals(ambient, select=[45.0, 12.0])
    mm = an.modal
    assert len(mm) == 2
    assert mm.natural_frequencies[0] == pytest.approx(12.0, rel=2e-3)
    assert mm.natural_frequencies[1] == pytest.approx(45.0, rel=2e-3)
    with pytest.raises(ValueError, match="no pole within"):
        pick_poles(an.identification.stabilization, [200.0])


def test_selection_rejects_with_reasons():
    """Each criterion rejects with its reason; a NaN damping (not estimated) is kept."""
    shapes = np.array([[1, 0.5], [1, 0.5], [1, 1j], [1, -0.5], [1, 0.2]], complex)
    mm = ModalModel(natural_frequencies=[5.0, 20.0, 30.0, 40.0, 90.0], damping_ratios=[0.01, 0.3, 0.01, np.nan, 0.01],
                    shapes=shapes, points=["a", "b"], method="x")
    sel = select_modes(mm, fmin=1.0, fmax=50.0, rejected=[RejectedMode(7.0, 0.01, "upstream")])
    assert list(sel.modes.natural_frequencies) == [5.0, 40.0]
    reasons = {r.natural_frequency: r.reason for r in sel.rejected}
    assert "damping 30 %" in reasons[20.0]
    assert "MPC 0.00" in reasons[30.0]
    assert "above the band" in reasons[90.0]
    assert reasons[7.0] == "upstream"
    assert [r.natural_frequency for r in sel.rejected] == sorted(reasons)
    coh = (np.array([0.0, 5.0, 40.0]), np.array([1.0, 0.2, 0.9]))
    assert list(select_modes(mm, fmax=50.0, coherence=coh).modes.natural_frequencies) == [40.0]


def test_bands_from_the_data():
    """The input's band: where its PSD is within 20 dB of the maximum; the response band: the
    lowest resonance, and 95 % of the variance."""
    f = np.linspace(0, 100, 1001)
    p = np.where((f >= 10) & (f <= 60), 1.0, 1e-4)
    assert excited_band(f, p) == (10.0, 60.0)
    psd = 1e-6 + 1.0 / (1 + ((f - 20) / 0.2) ** 2) + 0.5 / (1 + ((f - 50) / 0.3) ** 2)
    f_low, fmax = response_band(f, psd)
    assert f_low == pytest.approx(20.0, abs=0.11)
    assert 50.0 <= fmax < 60.0


def test_modes_document_schema(ambient):
    """MODES.json as the issue fixes it."""
    an = analyse_signals(ambient, fmax=100.0)
    doc = json.loads(json.dumps(modes_document(an.modal, an.identification.rejected)))
    assert doc["method"] == "ssi_cov"
    m = doc["modes"][0]
    assert set(m) == {"frequency_hz", "damping_ratio", "frequency_std_hz", "damping_std", "shape", "mpc", "mpd",
                      "stable"}
    assert set(m["shape"]) == set(an.modal.points) and all(len(v) == 2 for v in m["shape"].values())
    assert m["stable"] is True and 0.9 < m["mpc"] <= 1.0 and m["mpd"] < 10
    assert all(set(r) == {"frequency_hz", "damping_ratio", "reason"} for r in doc["rejected"])


def test_periodic_input_is_analysed_period_synchronously():
    """A random-phase multisine repeated 10 times: the period is found from the input, the FRFs
    use whole periods with a rectangular window (the first period dropped), and LSCF gives the
    five modes with their damping (no leakage bias from a Hann window)."""
    n, periods = 8192, 10
    rng = np.random.default_rng(7)
    k = np.arange(1, n // 2)
    lines = k[(k * FS / n > 5.0) & (k * FS / n < 100.0)]
    X = np.zeros(n // 2 + 1, complex)
    X[lines] = np.exp(2j * np.pi * rng.random(lines.size))
    one = np.fft.irfft(X, n)
    u = np.tile(one / one.std(), periods)
    sig = simulate(MODEL, u, FS, noise=0.02, seed=8)
    an = analyse_signals(sig, input=MODEL.input_channels()[0])
    assert any("periodic input: period" in w and f"({n} samples" in w for w in an.warnings), an.warnings
    assert an.frf.estimator == "periodic" and an.frf.settings["window"] == "boxcar"
    _assert_matches_truth(an.modal, z_tol=0.03)


def test_every_method_states_and_keeps_its_normalisation(ambient, forced):
    """ModalModel does what its docstring says: unit maximum (largest entry exactly 1) unless
    ``extra["normalisation"]`` says unit modal mass."""
    models = [analyse_signals(ambient, method=m).modal for m in ("ssi", "fdd", "efdd")]
    models += [analyse_signals(forced, input=MODEL.input_channels()[0], method=m).modal for m in ("lscf", "peak")]
    for mm in models:
        assert mm.extra.get("normalisation", "unit_maximum") == "unit_maximum", mm.method
        assert len(mm) >= 3, mm.method
        np.testing.assert_allclose(np.abs(mm.shapes).max(axis=1), 1.0, rtol=1e-12)
        k = np.argmax(np.abs(mm.shapes), axis=1)
        np.testing.assert_allclose(mm.shapes[np.arange(len(mm)), k], 1.0, rtol=1e-12)


def test_polymax_on_output_spectra_cross_checks_ssi(ambient):
    """polyMAX on the positive power spectra (exponential window removed from the damping)."""
    an = analyse_signals(ambient, method="polymax")
    assert an.modal.method == "polymax_oma"
    _assert_matches_truth(an.modal, z_tol=0.05, mac_min=0.95)  # shapes: the quick LSFD of the diagram


def test_lscf_bootstrap_random_error(forced):
    """The block bootstrap of the cross-spectra gives positive, small spreads for every mode."""
    from vibroscope.modal.uncertainty import lscf_bootstrap

    an = analyse_signals(forced, input=MODEL.input_channels()[0], nperseg=4096)
    u = lscf_bootstrap(forced, MODEL.input_channels()[0], MODEL.output_channels(), an.modal, nperseg=4096,
                       order=40, fmin=5.0, fmax=100.0)
    assert np.all(np.isfinite(u.frequency_std_hz)) and np.all(u.frequency_std_hz > 0)
    assert np.all(u.frequency_std_hz / an.modal.natural_frequencies < 1e-3)
    assert np.all(u.damping_std / an.modal.damping_ratios < 0.1)
    assert "random error only" in u.method


def test_identification_entry_points_run_on_one_blas_thread():
    """BLAS oversubscription (issue #9): auto_ssi, auto_lscf and polymax_oma bound every BLAS pool
    to one thread for their duration, and restore it after."""
    from threadpoolctl import threadpool_info

    from vibroscope.modal import automatic

    def blas_threads():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    before = blas_threads()
    assert set(automatic.one_blas_thread(blas_threads)()) == {1}
    assert blas_threads() == before
    for name in ("auto_ssi", "auto_lscf", "polymax_oma"):
        assert getattr(automatic, name).__wrapped__.__name__ == name
