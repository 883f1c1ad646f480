"""Output-only modal identification: Frequency Domain Decomposition (FDD) and Enhanced FDD (EFDD)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.fft
import scipy.signal

from vibroscope._checks import UnpacksAsTuple, axis_summary, names_summary, read_only
from vibroscope.modal._peaks import band_indices, parabolic_peak, parabolic_vertex
from vibroscope.modal._results import ModalModel, mpc, normalize_shapes
from vibroscope.modal.mac import mac
from vibroscope.spectral import CrossSpectralMatrix

__all__ = ["fdd", "singular_values", "efdd_damping", "SingularValues"]

_TINY = np.finfo(float).tiny


def _svd(csd: CrossSpectralMatrix):
    G = np.asarray(csd.G)
    # G[f] = E[conj(X) Xᵀ] is Hermitian PSD; its SVD equals the eigen-decomposition
    U, S, _ = np.linalg.svd(G, hermitian=True)
    return U, S


def _db(x: np.ndarray) -> np.ndarray:
    """``10 log10 x`` with zeros floored at the smallest positive float."""
    return 10 * np.log10(np.maximum(x, _TINY))


@dataclass(frozen=True, eq=False)
class SingularValues(UnpacksAsTuple):
    """Singular values of a cross-spectral matrix at every frequency (:func:`singular_values`).

    Unpacks like the tuple ``(frequencies, S)``.

    Attributes
    ----------
    frequencies : ndarray, shape (n_f,)
        Hz.
    S : ndarray, shape (n_f, n_ch)
        Singular values in descending order at each frequency, in the units of ``G`` (e.g.
        (m/s²)²/Hz).
    channels : tuple of str
        The channels of the cross-spectral matrix.
    settings : dict
        Its Welch settings.
    """

    frequencies: np.ndarray
    S: np.ndarray
    channels: tuple[str, ...] = ()
    settings: dict = field(default_factory=dict)

    _tuple_fields = ("frequencies", "S")

    def __post_init__(self) -> None:
        object.__setattr__(self, "frequencies", read_only(self.frequencies, float))
        object.__setattr__(self, "S", read_only(self.S, float))
        object.__setattr__(self, "channels", tuple(self.channels))

    def __repr__(self) -> str:
        return (f"SingularValues({self.S.shape[-1]} of {len(self.channels)} channels {names_summary(self.channels)}, "
                f"{axis_summary(self.frequencies)})")


def singular_values(csd: CrossSpectralMatrix) -> SingularValues:
    """Singular values of the cross-spectral matrix at every frequency (for the FDD plot).

    Parameters
    ----------
    csd : CrossSpectralMatrix
        ``G[f, i, j]`` of the responses, shape (n_f, n_ch, n_ch).

    Returns
    -------
    SingularValues
        Unpacks as ``(frequencies, S)``: frequencies in Hz, shape (n_f,), and the singular values
        in descending order at each frequency, shape (n_f, n_ch), in the units of `G`
        (e.g. (m/s²)²/Hz).
    """
    return SingularValues(csd.frequencies, _svd(csd)[1], csd.channels, dict(csd.settings or {}))


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
    frequencies: np.ndarray,
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
    frequencies : ndarray, shape (n_f,)
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
    n_f = len(frequencies)
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
    # refine extrema (never at the ends: argrelmax/argrelmin) by parabolic interpolation
    vertices = np.array([parabolic_vertex(r, k) for k in ext])
    te, ae = t[ext] + vertices[:, 0] / fs, np.abs(vertices[:, 1])
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
    mac_min: float = 0.8,
    mac_duplicate: float = 0.9,
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
       prominence; one whose shape has MAC > `mac_duplicate` with an already accepted mode and
       lies inside that mode's bell (all bins between them have MAC(u1(f), φ) > `mac_min`) is the
       same mode and is rejected.
    2. **EFDD** (Brincker, Ventura & Andersen 2001): the SDOF bell of each mode is the set of
       contiguous bins around the peak where the first (or second) singular vector has
       MAC > `mac_min` with the shape; its singular values, zero elsewhere, are taken back to
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
    mac_min : float, optional
        Smallest MAC accepted into a mode's SDOF bell: a bin belongs to the bell while the MAC of
        its singular vector with the mode's shape is above `mac_min`; default 0.8 (Brincker et al.).
    mac_duplicate : float, optional
        MAC above which a candidate inside an accepted mode's bell is the same mode (a
        duplicate, rejected); default 0.9.
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
        A peak is a mode only if its singular vector keeps MAC > `mac_min` over at least
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

    See Also
    --------
    vibroscope.spectral.csd_matrix : The cross-spectral matrix this decomposes.
    singular_values : The singular-value spectra alone (the FDD plot).
    ssi_cov : Output-only poles from the time series (SSI-COV).
    lscf : Poles from measured FRFs (input and output).
    peak_picking : The input-output counterpart (peaks of an FRF).

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

    Examples
    --------
    One mode at 5 Hz (a resonator driven by white noise), seen by two sensors in antiphase with
    5 % noise each: its frequency and shape.

    >>> import numpy as np, scipy.signal
    >>> from vibroscope.spectral import csd_matrix
    >>> rng = np.random.default_rng(0)
    >>> b, a = scipy.signal.iirpeak(5.0, Q=25.0, fs=100.0)
    >>> x = np.outer([1.0, -0.5], scipy.signal.lfilter(b, a, rng.standard_normal(20_000)))
    >>> x += 0.05 * x.std(axis=1, keepdims=True) * rng.standard_normal(x.shape)
    >>> mm = fdd(csd_matrix(x, fs=100.0, nperseg=1024), n_modes=1)
    >>> mm.method, len(mm), round(float(mm.natural_frequencies[0]), 1)
    ('efdd', 1, 5.0)
    >>> np.round(mm.shapes.real, 3)
    array([[ 1. , -0.5]])
    """
    if csd.G.shape[1] < 2:
        raise ValueError(f"FDD needs at least 2 channels, got {csd.G.shape[1]}")
    f_all = np.asarray(csd.frequencies)
    U, S = _svd(csd)
    idx = band_indices(f_all, fmin, fmax)
    candidates = _peak_candidates(S, idx, prominence, n_singular, sv_ratio_db)
    peaks = _distinct_peaks(candidates, U, S, mac_min, mac_duplicate, min_bell_bins, n_modes)
    if n_modes is not None and len(peaks) < n_modes:
        warnings.warn(f"found {len(peaks)} distinct peaks above {prominence=} dB, fewer than {n_modes=}",
                      stacklevel=2)
    fs = float((csd.settings or {}).get("fs", 2 * f_all[-1]))
    nfft = (csd.settings or {}).get("nfft")
    nfft = int(nfft) if nfft else 2 * (len(f_all) - 1)
    lagw = _window_lag_weights(csd, nfft // 2) if window_correction else None
    rows = [_refine_peak(pk, f_all, S, fs, nfft, lagw, efdd, max_level, min_level) for pk in peaks]
    failed = [r["frequency_peak"] for r in rows if r["efdd_failed"]]
    if failed:
        warnings.warn(f"EFDD could not fit the modes at {np.round(failed, 4).tolist()} Hz "
                      "(bell too narrow or decay longer than the segment); FDD peak kept, damping NaN",
                      stacklevel=2)
    shapes = normalize_shapes(np.array([pk.shape for pk in peaks]).reshape(len(peaks), U.shape[1]))

    def column(key, dtype=float):
        return np.array([r[key] for r in rows], dtype=dtype)

    extra = {
        "frequency_peak": column("frequency_peak"),
        "peak_value": column("peak_value"),
        "prominence": np.array([pk.prominence for pk in peaks], dtype=float),
        "bell_bins": np.array([pk.hi - pk.lo + 1 for pk in peaks], dtype=int),
        "singular_value": np.array([pk.q for pk in peaks], dtype=int),
        "n_extrema": column("n_extrema", int),
        "mpc": mpc(shapes) if len(peaks) else np.zeros(0),
        "settings": dict(fmin=fmin, fmax=fmax, prominence=prominence, mac_min=mac_min,
                         mac_duplicate=mac_duplicate, efdd=efdd, max_level=max_level, min_level=min_level,
                         window_correction=window_correction, n_singular=n_singular, csd=dict(csd.settings or {})),
    }
    return ModalModel(natural_frequencies=column("fn"), damping_ratios=column("zeta"), shapes=shapes,
                      points=csd.channels, method="efdd" if efdd else "fdd", extra=extra)


def _peak_candidates(S: np.ndarray, idx: np.ndarray, prominence: float, n_singular: int,
                     sv_ratio_db: float) -> list[tuple[int, float, int]]:
    """``(bin, prominence in dB, singular value q)`` of every peak of ``s_q`` in the band: those of
    ``s1`` by decreasing prominence, then those of ``s2`` ... that reach ``s1 − sv_ratio_db``."""
    db1 = _db(S[:, 0])
    out = []
    for q in range(min(int(n_singular), S.shape[1])):
        dbq = _db(S[:, q])
        pk, props = scipy.signal.find_peaks(dbq[idx], prominence=prominence)
        if q > 0:  # higher singular values: only peaks comparable with s1 there
            ok = dbq[idx[pk]] >= db1[idx[pk]] - sv_ratio_db
            pk, props = pk[ok], {k: v[ok] for k, v in props.items()}
        o = np.argsort(props["prominences"])[::-1]
        out += [(int(k), float(p), q) for k, p in zip(idx[pk][o], props["prominences"][o])]
    return out


@dataclass(frozen=True, eq=False, kw_only=True)
class _Peak:
    """An accepted FDD peak: its bin, singular value, shape, prominence and SDOF bell."""

    k: int
    q: int
    shape: np.ndarray
    prominence: float
    bell: np.ndarray
    lo: int
    hi: int


def _bell(U: np.ndarray, S: np.ndarray, k: int, q: int, phi: np.ndarray, mac_min: float,
          limits: tuple[int, int] | None = None):
    """The SDOF bell of the peak of ``s_q`` at bin `k` with shape `phi`: the singular values over
    the full axis (zero outside) and its index range ``[lo, hi]``. A neighbouring bin belongs to it
    while ``u1`` (else ``u2``) there has MAC > `mac_min` with `phi`, and lies within `limits`
    (inclusive bins: the minima of ``s_q`` towards the neighbouring peaks, :func:`_valley_limits`)."""
    n = S.shape[0]
    b = np.zeros(n)
    b[k] = S[k, q]
    lo = hi = k
    first, last = (1, n - 1) if limits is None else limits
    for step in (-1, 1):
        j = k + step
        while 0 < j < n and first <= j <= last:
            m1 = mac(phi, U[j, :, 0])[0, 0]
            m2 = mac(phi, U[j, :, 1])[0, 0] if U.shape[2] > 1 else 0.0
            if m1 > mac_min:
                b[j] = S[j, 0]
            elif m2 > mac_min:
                b[j] = S[j, 1]
            else:
                break
            if step < 0:
                lo = j
            else:
                hi = j
            j += step
    return b, lo, hi


def _valley_limits(s: np.ndarray, k: int, tops: np.ndarray) -> tuple[int, int]:
    """Bins ``(first, last)`` a bell around the peak at `k` may span: up to the lowest value of `s`
    between `k` and the nearest other peak `tops` on each side (the whole axis where there is none).
    With two or three channels, nearby modes can keep MAC above the threshold across both peaks,
    and a bell spanning two peaks gives a frequency between them (Brincker & Ventura, *Introduction
    to Operational Modal Analysis*, 2015, §10.3: the bell is one mode's neighbourhood)."""
    n = s.size
    left, right = tops[tops < k], tops[tops > k]
    first = 1 if left.size == 0 else int(left[-1] + np.argmin(s[left[-1] : k + 1]))
    last = n - 1 if right.size == 0 else int(k + np.argmin(s[k : right[0] + 1]))
    return first, last


def _distinct_peaks(candidates, U, S, mac_min: float, mac_duplicate: float, min_bell_bins: int,
                    n_modes: int | None) -> list[_Peak]:
    """Accept candidates in order, skipping duplicates of accepted modes (MAC > `mac_duplicate`
    inside their bell), second-singular-value peaks on an accepted bin, and bells narrower than
    `min_bell_bins` (noise); at most `n_modes`. Returned by increasing frequency."""
    accepted: list[_Peak] = []
    tops = np.array(sorted({k for k, _p, q in candidates if q == 0}), dtype=int)
    for k, prom, q in candidates:
        phi = U[k, :, q]
        if any(mac(phi, a.shape)[0, 0] > mac_duplicate and a.lo <= k <= a.hi for a in accepted):
            continue
        if q > 0 and any(a.k == k for a in accepted):
            continue
        bell, lo, hi = _bell(U, S, k, q, phi, mac_min, _valley_limits(S[:, q], k, tops))
        if hi - lo + 1 < min_bell_bins:  # incoherent from bin to bin: noise, not a mode
            continue
        accepted.append(_Peak(k=k, q=q, shape=phi, prominence=prom, bell=bell, lo=lo, hi=hi))
        if n_modes is not None and len(accepted) >= n_modes:
            break
    return sorted(accepted, key=lambda a: a.k)


def _refine_peak(pk: _Peak, f_all, S, fs: float, nfft: int, lagw, efdd: bool, max_level: float,
                 min_level: float) -> dict:
    """Frequency (parabolic peak, then EFDD inside the bell) and damping (EFDD) of one peak."""
    dbq = _db(S[:, pk.q])
    f_peak = parabolic_peak(f_all, dbq, pk.k)
    fn, zeta, n_ext, failed = f_peak, np.nan, 0, False
    if efdd:
        fe, ze, n_ext = efdd_damping(f_all, pk.bell, fs, nfft=nfft, lag_weights=lagw,
                                     max_level=max_level, min_level=min_level)
        df = f_all[1] - f_all[0]
        if np.isfinite(fe) and ze > 0 and f_all[pk.lo] - df <= fe <= f_all[pk.hi] + df:
            fn, zeta = fe, ze
        else:
            failed = True
    return {"fn": fn, "zeta": zeta, "frequency_peak": f_peak, "peak_value": dbq[pk.k], "n_extrema": n_ext,
            "efdd_failed": failed}
