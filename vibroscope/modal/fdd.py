"""Output-only modal identification: Frequency Domain Decomposition (FDD) and Enhanced FDD (EFDD)."""

from __future__ import annotations

import warnings

import numpy as np
import scipy.fft
import scipy.signal

from vibroscope.modal._results import ModalModel, mpc, normalize_shapes
from vibroscope.modal.mac import mac
from vibroscope.spectral import CrossSpectralMatrix

__all__ = ["fdd", "singular_values", "efdd_damping"]


def _svd(csd: CrossSpectralMatrix):
    G = np.asarray(csd.G)
    # G[f] = E[conj(X) Xᵀ] is Hermitian PSD; its SVD equals the eigen-decomposition
    U, S, _ = np.linalg.svd(G, hermitian=True)
    return U, S


def singular_values(csd: CrossSpectralMatrix) -> tuple[np.ndarray, np.ndarray]:
    """Singular values of the cross-spectral matrix at every frequency (for the FDD plot).

    Parameters
    ----------
    csd : CrossSpectralMatrix
        ``G[f, i, j]`` of the responses, shape (n_f, n_ch, n_ch).

    Returns
    -------
    frequencies : ndarray, shape (n_f,)
        Hz.
    S : ndarray, shape (n_f, n_ch)
        Singular values in descending order at each frequency, in the units of `G`
        (e.g. (m/s²)²/Hz).
    """
    return np.asarray(csd.frequencies), _svd(csd)[1]


def _window_lag_weights(csd: CrossSpectralMatrix, n: int) -> np.ndarray | None:
    """Normalised autocorrelation of the Welch window at lags 0..n-1 (None if unknown)."""
    st = csd.settings or {}
    win, nperseg = st.get("window"), st.get("nperseg")
    if win is None or nperseg is None or win == "custom":
        return None
    try:
        w = scipy.signal.get_window(win, int(nperseg), fftbins=True)
    except (ValueError, TypeError):
        return None
    c = np.correlate(w, w, mode="full")[len(w) - 1 :] / np.sum(w**2)
    out = np.zeros(n)
    m = min(n, c.size)
    out[:m] = c[:m]
    return out


def efdd_damping(
    f: np.ndarray,
    bell: np.ndarray,
    fs: float,
    *,
    nfft: int | None = None,
    lag_weights: np.ndarray | None = None,
    max_level: float = 0.9,
    min_level: float = 0.1,
    min_weight: float = 0.25,
) -> tuple[float, float, int]:
    """Frequency and damping of one SDOF spectral bell by its correlation function (EFDD).

    The bell (zero outside the mode's band) is taken back to the lag domain by an inverse real FFT,
    normalised, and optionally divided by the window's lag weights (the bias of Welch averaging).
    The extrema between `max_level` and `min_level` give the decay rate σ by a linear fit of
    ``ln|r|`` against time; the zero crossings give the damped period by a linear fit of their times.
    Then ``ωn = sqrt(ωd² + σ²)`` and ``ζ = σ / ωn`` (equivalent to the logarithmic decrement
    ``δ = 2π ζ / sqrt(1 − ζ²)``).

    Parameters
    ----------
    f : ndarray, shape (n_f,)
        The full one-sided frequency axis in Hz (0 … fs/2).
    bell : ndarray, shape (n_f,)
        The SDOF spectral density (zero outside the mode's bell).
    fs : float
        Sampling frequency in Hz.
    nfft : int, optional
        FFT length of the spectral estimate (default ``2 (n_f − 1)``).
    lag_weights : ndarray, optional
        Normalised window autocorrelation per lag (see Notes); lags with weight below `min_weight`
        are not used.
    max_level, min_level : float, optional
        Range of the normalised correlation envelope used (defaults 0.9 and 0.1).
    min_weight : float, optional
        Smallest lag weight used (default 0.25).

    Returns
    -------
    fn : float
        Natural frequency in Hz (NaN if fewer than 3 extrema are usable).
    zeta : float
        Damping ratio (dimensionless; NaN likewise).
    n_extrema : int
        Number of extrema used.

    Notes
    -----
    The Welch estimate is the Fourier transform of the true correlation multiplied by the
    normalised window autocorrelation ``Σ w[n] w[n+m] / Σ w²``; dividing by it removes most of the
    window's damping bias for lags well inside the segment.
    """
    n_f = len(f)
    nfft = 2 * (n_f - 1) if nfft is None else int(nfft)
    r = scipy.fft.irfft(bell, n=nfft)[: nfft // 2]
    if r[0] <= 0:
        return np.nan, np.nan, 0
    r = r / r[0]
    n_use = len(r)
    if lag_weights is not None:
        lw = lag_weights[: len(r)]
        good = lw >= min_weight
        n_use = int(np.argmin(good)) if not good.all() else len(r)
        r = r[:n_use] / lw[:n_use]
    t = np.arange(n_use) / fs
    ext = np.sort(np.concatenate([scipy.signal.argrelmax(r)[0], scipy.signal.argrelmin(r)[0]]))
    if ext.size == 0:
        return np.nan, np.nan, 0
    amp = np.abs(r[ext])
    # refine extrema by parabolic interpolation
    te, ae = [], []
    for k in ext:
        a, b, c = r[k - 1], r[k], r[k + 1] if k + 1 < n_use else r[k]
        den = a - 2 * b + c
        p = 0.5 * (a - c) / den if den != 0 else 0.0
        p = float(np.clip(p, -0.5, 0.5))
        te.append(t[k] + p / fs)
        ae.append(abs(b - 0.25 * (a - c) * p))
    te, ae = np.array(te), np.array(ae)
    # the envelope window: from the first extremum below max_level to the first below min_level
    below_max = np.flatnonzero(amp <= max_level)
    if below_max.size == 0:
        return np.nan, np.nan, 0
    i0 = below_max[0]
    below_min = np.flatnonzero(amp[i0:] < min_level)
    i1 = i0 + (below_min[0] if below_min.size else len(amp) - i0)
    sel = slice(i0, i1)
    if i1 - i0 < 3:
        return np.nan, np.nan, int(i1 - i0)
    sigma = -np.polyfit(te[sel], np.log(ae[sel]), 1)[0]
    # zero crossings within the same time span
    s = np.signbit(r)
    zc = np.flatnonzero(s[1:] != s[:-1])
    tz = t[zc] + (r[zc] / (r[zc] - r[zc + 1])) / fs
    tz = tz[(tz >= te[i0] - 1.0 / fs) & (tz <= te[i1 - 1] + 1.0 / fs)]
    if tz.size >= 3:
        half_period = np.polyfit(np.arange(tz.size), tz, 1)[0]
    else:
        half_period = np.median(np.diff(te[sel]))
    wd = np.pi / half_period
    wn = np.sqrt(wd**2 + sigma**2)
    return float(wn / (2 * np.pi)), float(sigma / wn), int(i1 - i0)


def fdd(
    csd: CrossSpectralMatrix,
    *,
    n_modes: int | None = None,
    fmin: float | None = None,
    fmax: float | None = None,
    prominence: float = 6.0,
    mac_threshold: float = 0.8,
    mac_reject: float = 0.9,
    efdd: bool = True,
    max_level: float = 0.9,
    min_level: float = 0.1,
    window_correction: bool = True,
    n_singular: int = 1,
    min_bell_bins: int = 3,
    sv_ratio_db: float = 20.0,
) -> ModalModel:
    """Output-only modal parameters by Frequency Domain Decomposition, damping by EFDD.

    1. **FDD** (Brincker, Zhang & Andersen 2001): ``G(f) = U(f) S(f) U(f)ᴴ`` at every frequency;
       peaks of the first singular value ``s1(f)`` (in dB, :func:`scipy.signal.find_peaks` with
       `prominence`) are the modes and ``u1`` at the peak is the mode shape, normalised to unit
       maximum modulus with a real positive reference. Candidates are taken by decreasing
       prominence; one whose shape has MAC > `mac_reject` with an already accepted mode and lies
       inside that mode's bell (all bins between them have MAC(u1(f), φ) > `mac_threshold`) is the
       same mode and is rejected.
    2. **EFDD** (Brincker, Ventura & Andersen 2001): the SDOF bell of each mode is the set of
       contiguous bins around the peak where the first (or second) singular vector has
       MAC > `mac_threshold` with the shape; its singular values, zero elsewhere, are taken back to
       the correlation function by an inverse FFT (:func:`efdd_damping`): the logarithmic
       decrement of the envelope gives the damping and the zero crossings refine the frequency.

    Parameters
    ----------
    csd : CrossSpectralMatrix
        ``G[f, i, j]`` of the response channels, shape (n_f, n_ch, n_ch), from
        :func:`vibroscope.spectral.csd_matrix`. Damping needs fine resolution: the bell should span
        many bins (Δf ≪ 2 ζ fn) and the segment be longer than the correlation decay ``1/(2π ζ fn)``.
    n_modes : int, optional
        Keep the `n_modes` most prominent accepted peaks (sorted by frequency); default all.
    fmin, fmax : float, optional
        Band in Hz searched for peaks (default the whole axis above 0 Hz).
    prominence : float, optional
        Smallest prominence of a peak of ``10 log10 s1`` in dB; default 6 dB.
    mac_threshold : float, optional
        MAC defining a mode's SDOF bell; default 0.8 (Brincker et al.).
    mac_reject : float, optional
        MAC above which a candidate inside an accepted mode's bell is a duplicate; default 0.9.
    efdd : bool, optional
        Estimate damping and refine frequency by EFDD (default); otherwise damping is NaN and the
        frequency is the parabola-interpolated peak.
    max_level, min_level : float, optional
        Normalised correlation envelope range used by EFDD; defaults 0.9 and 0.1.
    window_correction : bool, optional
        Divide the correlation function by the Welch window's normalised autocorrelation (from
        ``csd.settings``) before the decay fit; default True.
    n_singular : int, optional
        Number of singular values searched for peaks (default 1, classic FDD). With 2, peaks of
        ``s2`` are candidates too (shape ``u2`` at the peak), which separates two close modes
        that share one peak of ``s1`` (e.g. the two bending directions of a tower); they are
        taken after all ``s1`` candidates and pass the same duplicate test.
    min_bell_bins : int, optional
        A peak is a mode only if its singular vector keeps MAC > `mac_threshold` over at least
        this many bins (default 3: a Hann window spreads even the lightest-damped mode over its
        main lobe, while a noise peak's singular vector is random from bin to bin).
    sv_ratio_db : float, optional
        A peak of ``s_q`` (q > 0) is a candidate only if ``s_q ≥ s1 · 10^(−sv_ratio_db/10)`` there
        (default 20 dB): with a single source the higher singular values are the noise floor,
        whose bumps under each mode are not modes.

    Returns
    -------
    ModalModel
        ``method='efdd'`` (or ``'fdd'``); points are the csd channels. ``extra`` holds per-mode
        arrays ``"frequency_peak"`` (Hz, parabolic peak), ``"peak_value"`` (singular value at the peak,
        dB), ``"singular_value"`` (0 for s1, 1 for s2),
        ``"prominence"`` (dB), ``"bell_bins"``, ``"n_extrema"``, ``"mpc"`` and the settings.

    Raises
    ------
    ValueError
        If the band holds fewer than 5 bins or the matrix has fewer than 2 channels.

    Notes
    -----
    Where EFDD cannot fit (fewer than 3 usable extrema, e.g. a bell of a few bins, a decay longer
    than the segment giving a non-positive decay rate, or a frequency outside the bell), the FDD
    peak frequency is kept and the damping is NaN; a warning says so.

    References
    ----------
    .. [1] R. Brincker, L. Zhang and P. Andersen, "Modal identification of output-only systems using
       frequency domain decomposition", Smart Materials and Structures 10, 441–445, 2001.
    .. [2] R. Brincker, C. E. Ventura and P. Andersen, "Damping estimation by frequency domain
       decomposition", Proc. 19th IMAC, 698–703, 2001.
    """
    if csd.G.shape[1] < 2:
        raise ValueError(f"FDD needs at least 2 channels, got {csd.G.shape[1]}")
    f_all = np.asarray(csd.frequencies)
    U, S = _svd(csd)
    s1 = S[:, 0]
    band = f_all > 0
    if fmin is not None:
        band &= f_all >= fmin
    if fmax is not None:
        band &= f_all <= fmax
    idx = np.flatnonzero(band)
    if idx.size < 5:
        raise ValueError(f"the band {fmin=} .. {fmax=} Hz holds {idx.size} bins; at least 5 are needed")
    tiny = np.finfo(float).tiny
    cand_l, prom_l, sv_l = [], [], []
    for q in range(min(int(n_singular), S.shape[1])):
        dbq = 10 * np.log10(np.maximum(S[:, q], tiny))
        pk, props = scipy.signal.find_peaks(dbq[idx], prominence=prominence)
        if q > 0:  # higher singular values: only peaks comparable with s1 there
            ok = dbq[idx[pk]] >= 10 * np.log10(np.maximum(s1[idx[pk]], tiny)) - sv_ratio_db
            pk, props = pk[ok], {k: v[ok] for k, v in props.items()}
        o = np.argsort(props["prominences"])[::-1]
        cand_l += list(idx[pk][o])
        prom_l += list(props["prominences"][o])
        sv_l += [q] * len(o)
    cand, prom, sv = np.array(cand_l, dtype=int), np.array(prom_l), np.array(sv_l, dtype=int)
    order = np.arange(len(cand))

    def bell_of(k: int, q: int, phi: np.ndarray) -> tuple[np.ndarray, int, int]:
        """Bell values over the full axis and its index range [lo, hi] (peak of singular value q)."""
        b = np.zeros_like(s1)
        b[k] = S[k, q]
        lo = hi = k
        for step in (-1, 1):
            j = k + step
            while 0 < j < len(s1):
                m1 = mac(phi, U[j, :, 0])[0, 0]
                m2 = mac(phi, U[j, :, 1])[0, 0] if U.shape[2] > 1 else 0.0
                if m1 > mac_threshold:
                    b[j] = S[j, 0]
                elif m2 > mac_threshold:
                    b[j] = S[j, 1]
                else:
                    break
                if step < 0:
                    lo = j
                else:
                    hi = j
                j += step
        return b, lo, hi

    accepted: list[int] = []
    acc_prom: list[float] = []
    acc_shape: list[np.ndarray] = []
    acc_sv: list[int] = []
    bells: list[tuple[np.ndarray, int, int]] = []
    for o in order:
        k = int(cand[o])
        phi = U[k, :, sv[o]]
        dup = False
        for a, (_, lo, hi) in enumerate(bells):
            if mac(phi, acc_shape[a])[0, 0] > mac_reject and lo <= k <= hi:
                dup = True
                break
        if dup or (sv[o] > 0 and k in accepted):
            continue
        bell = bell_of(k, int(sv[o]), phi)
        if bell[2] - bell[1] + 1 < min_bell_bins:  # incoherent from bin to bin: noise, not a mode
            continue
        accepted.append(k)
        acc_prom.append(float(prom[o]))
        acc_shape.append(phi)
        acc_sv.append(int(sv[o]))
        bells.append(bell)
        if n_modes is not None and len(accepted) >= n_modes:
            break
    if n_modes is not None and len(accepted) < n_modes:
        warnings.warn(f"found {len(accepted)} distinct peaks above {prominence=} dB, fewer than {n_modes=}",
                      stacklevel=2)
    srt = np.argsort(accepted, kind="stable")
    accepted = [accepted[i] for i in srt]
    acc_prom = [acc_prom[i] for i in srt]
    acc_shape = [acc_shape[i] for i in srt]
    acc_sv = [acc_sv[i] for i in srt]
    bells = [bells[i] for i in srt]

    fs = float((csd.settings or {}).get("fs", 2 * f_all[-1]))
    nfft = (csd.settings or {}).get("nfft")
    nfft = int(nfft) if nfft else 2 * (len(f_all) - 1)
    lagw = _window_lag_weights(csd, nfft // 2) if window_correction else None
    fn_l, z_l, fpk, pkv, nb, nex = [], [], [], [], [], []
    failed = []
    for m_i, k in enumerate(accepted):
        f_peak = float(f_all[k])
        dbq = 10 * np.log10(np.maximum(S[:, acc_sv[m_i]], tiny))
        if 0 < k < len(s1) - 1:
            a, b, c = dbq[k - 1], dbq[k], dbq[k + 1]
            den = a - 2 * b + c
            if den < 0:
                f_peak = float(f_all[k] + np.clip(0.5 * (a - c) / den, -0.5, 0.5) * (f_all[1] - f_all[0]))
        bell, lo, hi = bells[m_i]
        fn, zeta, n_ext = f_peak, np.nan, 0
        if efdd:
            fe, ze, n_ext = efdd_damping(f_all, bell, fs, nfft=nfft, lag_weights=lagw,
                                         max_level=max_level, min_level=min_level)
            if np.isfinite(fe) and ze > 0 and f_all[lo] - (f_all[1] - f_all[0]) <= fe <= f_all[hi] + (f_all[1] - f_all[0]):
                fn, zeta = fe, ze
            else:
                failed.append(f_peak)
        fn_l.append(fn)
        z_l.append(zeta)
        fpk.append(f_peak)
        pkv.append(dbq[k])
        nb.append(hi - lo + 1)
        nex.append(n_ext)
    if failed:
        warnings.warn(f"EFDD could not fit the modes at {np.round(failed, 4).tolist()} Hz "
                      "(bell too narrow or decay longer than the segment); FDD peak kept, damping NaN",
                      stacklevel=2)
    shapes = normalize_shapes(np.array(acc_shape).reshape(len(accepted), U.shape[1]))
    extra = {
        "frequency_peak": np.array(fpk),
        "peak_value": np.array(pkv),
        "prominence": np.array(acc_prom),
        "bell_bins": np.array(nb, dtype=int),
        "singular_value": np.array(acc_sv, dtype=int),
        "n_extrema": np.array(nex, dtype=int),
        "mpc": mpc(shapes) if len(accepted) else np.zeros(0),
        "settings": dict(fmin=fmin, fmax=fmax, prominence=prominence, mac_threshold=mac_threshold,
                         mac_reject=mac_reject, efdd=efdd, max_level=max_level, min_level=min_level,
                         window_correction=window_correction, n_singular=n_singular, csd=dict(csd.settings or {})),
    }
    return ModalModel(np.array(fn_l), np.array(z_l), shapes, csd.channels, "efdd" if efdd else "fdd", extra)
