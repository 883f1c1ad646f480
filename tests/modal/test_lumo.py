"""Output-only identification of the LUMO lattice tower (real data).

Data: Wernitz et al. (2021), LUMO — Leibniz University Test Structure for Monitoring [Dataset],
doi:10.25835/0027803 (``../shared/data/lumo``). Published natural frequencies (SSI-COV, as
reported with the modalyzer example; FDD/EFDD agree on the first four within 0.3 %): near 2.82,
13.55, 15.99, 16.33, 30.8, 40.5, 42.6 Hz, damping ratios about 0.2–0.3 % for the low modes.

Settings (stated): the 18 accelerations (9 heights × 2 directions, 1651 Hz, 60.6 s) are
decimated by 8 (zero-phase FIR, 206.4 Hz); Welch with ``nperseg=4096`` (Δf = 0.050 Hz, 19.8 s
segments, 5 averages with 50 % overlap) — finer resolution leaves too few averages for the
SVD; FDD searches the first two singular values (``n_singular=2``) so that the two nearly
coincident first bending modes (one per direction) are both found.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.signal

from vibroscope.modal import fdd, mac, ssi_cov
from vibroscope.spectral import csd_matrix

PUBLISHED_HZ = [2.82, 13.55, 15.99, 16.33]


@pytest.fixture(scope="module")
def lumo_raw(shared_data):
    """(accelerations (18, 100000) at 1651 Hz, sensor direction 1/2 per channel)."""
    path = shared_data / "lumo" / "data_lumo.csv"
    if not path.is_file():
        pytest.skip(f"{path} not found")
    acc = np.loadtxt(path, delimiter=",", usecols=range(18)).T
    coords = np.genfromtxt(shared_data / "lumo" / "coords_lumo.csv", delimiter=",", names=True)
    return acc, coords["direction"].astype(int)[:18]


@pytest.fixture(scope="module")
def lumo(lumo_raw):
    acc, direction = lumo_raw
    x = scipy.signal.decimate(acc, 8, axis=1, ftype="fir", zero_phase=True)
    G = csd_matrix(x, 1651.0 / 8, nperseg=4096)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # EFDD cannot fit the slowest decays in 20 s segments
        model = fdd(G, fmin=1.0, fmax=20.0, n_singular=2, prominence=10.0)
    return model, direction


def test_lumo_published_frequencies(lumo):
    model, _ = lumo
    f = model.natural_frequencies
    picked = []
    for fp in PUBLISHED_HZ:
        k = int(np.argmin(np.abs(f - fp)))
        assert abs(f[k] / fp - 1) < 0.01, (fp, f)
        picked.append(k)
    assert len(set(picked)) == len(PUBLISHED_HZ)  # four distinct identified modes


def test_lumo_first_bending_pair(lumo):
    """The two first bending modes (one per sensor direction, 2.78 and 2.81 Hz) are separated
    and their shapes are nearly orthogonal, growing with height."""
    model, direction = lumo
    low = np.flatnonzero(model.natural_frequencies < 3.2)
    assert len(low) == 2
    a, b = model.shapes[low]
    assert mac(a, b)[0, 0] < 0.2
    dom = {int(direction[np.argmax(np.abs(s))]) for s in (a, b)}
    assert dom == {1, 2}
    for s in (a, b):
        d = direction[np.argmax(np.abs(s))]
        mag = np.abs(s[direction == d])  # sensors ordered from the top (8.95 m) down
        assert np.all(np.diff(mag) < 0.02)


def test_lumo_damping_plausible(lumo):
    """EFDD damping of the 13.55 and 15.99 Hz modes is light (published ~0.2–0.3 %); with 20 s
    segments and Δf = 0.05 Hz it is resolution-limited, so only 0 < ζ < 1 % is checked."""
    model, _ = lumo
    for fp in (13.55, 15.99):
        k = int(np.argmin(np.abs(model.natural_frequencies - fp)))
        assert 0 < model.damping_ratios[k] < 0.01


def test_lumo_ssi_cov(lumo_raw):
    """SSI-COV (the published method) on the data decimated by 16 (103.2 Hz), 40 block rows
    (0.39 s of lags), orders 10–120: all four published low modes within 1 %, and the light
    damping of the 2.82 and 15.99 Hz modes between 0.1 % and 0.5 % (published ~0.2–0.3 %)."""
    acc, _ = lumo_raw
    x = scipy.signal.decimate(acc, 16, axis=1, ftype="fir", zero_phase=True)
    st = ssi_cov(x, 1651.0 / 16, n_lags=40, orders=range(10, 121, 4))
    model = st.modal_model(fmin=1.0, fmax=20.0)
    f = model.natural_frequencies
    for fp in PUBLISHED_HZ:
        k = int(np.argmin(np.abs(f - fp)))
        assert abs(f[k] / fp - 1) < 0.01, (fp, f)
    for fp in (2.82, 15.99):
        k = int(np.argmin(np.abs(f - fp)))
        assert 0.001 < model.damping_ratios[k] < 0.005, (fp, model.damping_ratios[k])


# ---------------------------------------------------------------- the defaults, with no option

#: published natural frequencies (Hz) of the seven modes (../shared/data/README.md), the first
#: bending pair (one mode per direction) counted once
PUBLISHED_ALL_HZ = [2.82, 13.55, 15.99, 16.33, 30.8, 40.5, 42.6]


@pytest.fixture(scope="module")
def lumo_default(lumo_raw):
    """``analyse_signals`` with no option (band from the data, decimation, SSI-COV, selection): the
    path of ``vibroscope analyse`` / ``vibroscope modal`` on the converted log."""
    from vibroscope import Signals
    from vibroscope.pipeline import analyse_signals

    acc, direction = lumo_raw
    sig = Signals(data=acc, fs=1651.0, channels=[f"/lumo/s{i + 1:02d}.linear_acceleration.x" for i in range(18)],
                  units=["m/s^2"] * 18)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ident = analyse_signals(sig).identification
    return ident.modes, direction


def test_lumo_defaults_find_the_published_modes_none_split(lumo_default):
    """With no option: the first bending pair (2.777 and 2.813 Hz: -1.5 % and -0.25 % from the
    published 2.82 Hz; the lower one sits 1.5 % low with every method on this 60 s record), and
    13.55, 15.99, 16.33, 40.5, 42.6 Hz within 1.5 % (40.5 Hz is found at 41.03 Hz, +1.3 %).

    No mode is reported twice: every two modes within 5 % of each other have different shapes
    (MAC < 0.5). The pair near 40.5 Hz, 39.81 and 41.03 Hz, is two modes, not one split: MAC 0.28;
    41.03 Hz is the y-direction third bending mode (two nodes along the height; its y shape has
    MAC > 0.7 with the x shape of the 42.56 Hz x-direction third bending mode, as 15.99/16.33 Hz
    pair as second bending), 39.81 Hz moves the y sensors in a one-node shape like that of the
    15.99 Hz second bending mode (MAC > 0.9) -- a mode the published list does not hold."""
    model, direction = lumo_default
    f = model.natural_frequencies
    assert np.sum(np.abs(f / 2.82 - 1) < 0.02) == 2, f  # one per direction
    for fp in (13.55, 15.99, 16.33, 40.5, 42.6):
        assert np.min(np.abs(f / fp - 1)) < 0.015, (fp, f)
    M = mac(model.shapes, model.shapes)
    close = np.abs(f[:, None] / f[None, :] - 1) < 0.05
    np.fill_diagonal(close, False)
    assert np.all(M[close] < 0.5), (f, np.round(M, 2))
    y, x = direction == 2, direction == 1
    k40, k42, k16 = (int(np.argmin(np.abs(f - v))) for v in (41.0, 42.6, 15.99))
    assert mac(model.shapes[k40][y], model.shapes[k42][x])[0, 0] > 0.7
    k39 = int(np.argmin(np.abs(f - 39.8)))
    assert abs(f[k39] / 39.8 - 1) < 0.01 and mac(model.shapes[k39][y], model.shapes[k16][y])[0, 0] > 0.9
    assert len(f) <= 9


@pytest.mark.xfail(strict=True, reason="30.8 Hz is not a stable pole of this 60 s record: a heavily damped "
                   "(4-9 %) pole with a consistent shape wanders over 30.5-32.2 Hz (1-4 % between consecutive "
                   "orders) at orders 24-52 and is never stable within the 1 % frequency tolerance")
def test_lumo_defaults_find_30_8_hz(lumo_default):
    """The published 30.8 Hz mode with no option (within 2 %).

    What the record holds there (issue 20 item 9): a broad plateau of the first singular value over
    27-34 Hz, about 5 dB above its surroundings (an SDOF fit over 22-38 Hz: 30.9 Hz, ζ 16 %), its
    singular vector the same over the plateau (MAC >= 0.85 with the vector at 30 Hz), 95 % in the y
    sensors with its largest motion at 4-5 m. SSI-COV gives a pole family of that shape (MAC mostly
    > 0.85) at 19 of the 29 orders, median 30.3 Hz and ζ 6.3 %, whose frequency moves 1-5 % from one
    order to the next (30.5-32.2 Hz at orders 24-52, 29.5-30.8 Hz at 68-120) and its damping 4-11 %:
    never stable within 1 % / 5 %. Nor is it reproducible: in 20 block-bootstrap replicates of the
    covariances (10 blocks) fewer than half hold it (within 2 %, MAC >= 0.8) at orders 24 and 40; at
    44 and 48 its spread is 0.41 and 0.10 Hz, ζ ± 2 %. pyOMA2's SSI-cov on the same decimated record
    (6 references, orders 8-120, its looser 5 % / 10 % / MAC 0.95 criteria, 30, 60 and 118 block
    rows) has at most 8 stable poles in 29-31 Hz, scattered (median 29.6-30.2 Hz, ζ 3-7 %), against
    21-29 for each published mode it finds. Frequency tolerances that widen with the pole's damping
    (max(1 %, ζ) or max(1 %, ζ/2)) make no 30-31 Hz cluster but add spurious ones (29.3 Hz ζ 2.8 %,
    33.4 Hz, a second 42.5 Hz); FDD peaks there only at some resolutions (30.7 Hz at nperseg 1024,
    beside noise peaks at 2048, none at 256 or 512)."""
    f = lumo_default[0].natural_frequencies
    assert np.min(np.abs(f / 30.8 - 1)) < 0.02, f
