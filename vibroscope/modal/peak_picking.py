"""Peak picking on measured FRFs: natural frequencies, half-power damping refined by a single-DOF
fit, and mode shapes by quadrature picking (Ewins 2000, ch. 4)."""

from __future__ import annotations

import warnings
from typing import Literal

import numpy as np
import scipy.optimize
import scipy.ndimage
import scipy.signal

from vibroscope.modal._results import ModalModel, mpc, normalize_shapes
from vibroscope.spectral import FRF
from vibroscope.spectral._engine import check_option

__all__ = ["peak_picking", "half_power_bandwidth", "fit_sdof"]


def _parabolic_peak(f: np.ndarray, y: np.ndarray, k: int) -> float:
    """Vertex of the parabola through bins k-1, k, k+1 of `y` (Hz)."""
    if k <= 0 or k >= len(y) - 1 or not np.all(np.isfinite(y[k - 1 : k + 2])):
        return float(f[k])
    a, b, c = y[k - 1], y[k], y[k + 1]
    den = a - 2 * b + c
    if den >= 0:
        return float(f[k])
    p = 0.5 * (a - c) / den
    return float(f[k] + np.clip(p, -0.5, 0.5) * (f[1] - f[0]))


def half_power_bandwidth(f: np.ndarray, power: np.ndarray, k: int) -> tuple[float, float]:
    """Half-power (−3 dB) frequencies around the peak bin `k` of a power-like curve.

    Walks left and right from `k` until `power` falls below ``power[k] / 2`` and interpolates the
    crossings linearly in dB between the two bins that bracket them.

    Parameters
    ----------
    f : ndarray, shape (n_f,)
        Frequencies in Hz.
    power : ndarray, shape (n_f,)
        A squared magnitude (``|H|²``, a PSD or a singular value), positive.
    k : int
        Index of the peak.

    Returns
    -------
    (f1, f2) : tuple of float
        Lower and upper half-power frequencies in Hz; NaN where the curve rises again (another
        peak) or ends before crossing.
    """
    half = power[k] / 2.0
    db = 10 * np.log10(np.maximum(power, np.finfo(float).tiny))
    hdb = 10 * np.log10(half)

    def walk(step: int) -> float:
        j = k
        while 0 <= j + step < len(power):
            nxt = j + step
            if power[nxt] < half:
                t = (db[j] - hdb) / (db[j] - db[nxt])
                return float(f[j] + t * (f[nxt] - f[j]))
            if power[nxt] > power[k]:
                return np.nan
            j = nxt
        return np.nan

    return walk(-1), walk(+1)


def fit_sdof(f: np.ndarray, H: np.ndarray, fn0: float, zeta0: float) -> tuple[float, float, np.ndarray, float]:
    """Least-squares single-DOF fit of receptances around one resonance, all channels together.

    Each column ``k`` of `H` is modelled as ``A_k / (ωr² − ω² + 2jζωrω) + R_k + M_k / ω²`` with a
    complex modal constant ``A_k`` and the complex upper (stiffness-like, ``R_k``) and lower
    (mass-like, ``M_k / ω²``) residuals standing for the out-of-band modes (Ewins 2000,
    ch. 4: the SDOF methods and residual terms). ``A``, ``R`` and ``M`` enter linearly and are eliminated (variable
    projection); ``(fr, ζ)`` are found by :func:`scipy.optimize.least_squares`. Columns are weighted
    to equal peak magnitude.

    Parameters
    ----------
    f : ndarray, shape (n_f,)
        Frequencies in Hz (a band around the resonance, at least 4 bins).
    H : ndarray, complex, shape (n_f, n_channels)
        Receptance-like FRFs (displacement per force, any units).
    fn0, zeta0 : float
        Starting natural frequency (Hz) and damping ratio.

    Returns
    -------
    fn : float
        Natural frequency in Hz.
    zeta : float
        Damping ratio (dimensionless).
    A : ndarray, complex, shape (n_channels,)
        Modal constants (units of `H` × rad²/s²).
    cost : float
        Relative residual norm ``‖H − fit‖ / ‖H‖`` of the weighted data.
    """
    w = 2 * np.pi * np.asarray(f, dtype=float)
    H = np.asarray(H, dtype=complex)
    if H.ndim == 1:
        H = H[:, None]
    scale = np.max(np.abs(H), axis=0)
    scale[scale == 0] = 1.0
    Hn = H / scale

    def basis(p):
        wr, z = 2 * np.pi * p[0], p[1]
        return np.column_stack([1.0 / (wr**2 - w**2 + 2j * z * wr * w), np.ones_like(w), 1.0 / w**2])

    def solve(p):
        Phi = basis(p)
        coef, *_ = np.linalg.lstsq(Phi, Hn, rcond=None)
        return Phi, coef

    def resid(p):
        Phi, coef = solve(p)
        r = (Hn - Phi @ coef).ravel()
        return np.concatenate([r.real, r.imag])

    lo = [f[0], 1e-6]
    hi = [f[-1], 0.5]
    p0 = [float(np.clip(fn0, f[0] + 1e-9, f[-1] - 1e-9)), float(np.clip(zeta0, 2e-6, 0.49))]
    sol = scipy.optimize.least_squares(resid, p0, bounds=(lo, hi), x_scale=[max(fn0, 1e-9) * 1e-3, max(zeta0, 1e-4)],
                                       method="trf")
    Phi, coef = solve(sol.x)
    A = coef[0] * scale
    cost = float(np.linalg.norm(Hn - Phi @ coef) / np.linalg.norm(Hn))
    return float(sol.x[0]), float(sol.x[1]), A, cost


def peak_picking(
    frf: FRF,
    *,
    n_modes: int | None = None,
    fmin: float | None = None,
    fmax: float | None = None,
    min_coherence: float = 0.8,
    prominence: float = 3.0,
    refine: Literal["sdof", None] = "sdof",
    input: int | str | None = None,
) -> ModalModel:
    """Modal parameters from FRFs by peak picking (the peak-amplitude method).

    1. **Peaks** of the mode indicator ``10 log10 mean_{o,i} |Y_oi|²`` (the power sum of all
       mobilities ``Y`` in the band), found with
       :func:`scipy.signal.find_peaks` at the given `prominence` (dB), on bins whose mean coherence
       reaches `min_coherence`; the frequency is refined by a parabola through the peak bin and its
       neighbours (in dB).
    2. **Damping** by the half-power (−3 dB) bandwidth of the indicator, crossings interpolated
       between bins (in dB): ``ζ = (f2 − f1) / (2 fn)`` (Ewins 2000, §4.3; exact for the mobility
       of a single viscously damped mode), then, with ``refine='sdof'``, a least-squares
       single-DOF fit (modal constant + upper and lower residuals per channel) of all receptances
       over ``fn ± (f2 − f1)`` (at least ± 4 bins; :func:`fit_sdof`, Ewins 2000, §4.4–4.5), which removes the bias of coarse resolution and
       of neighbouring modes. The fit result is used when it converges inside the band.
    3. **Shapes** by quadrature picking: the imaginary part of the accelerance at the natural
       frequency, sign kept, for every output (``Im α_acc ∝ φ_o φ_in / (2 ζ)`` for a lightly damped
       mode; Ewins 2000, §4.3 "quadrature response"), normalised to unit maximum modulus with a real
       positive reference (:func:`~vibroscope.modal.normalize_shapes`).

    Parameters
    ----------
    frf : FRF
        ``H[f, output, input]`` with a known `kind` (accelerance, mobility or receptance; converted
        with :meth:`FRF.to`) or an unknown kind (then used as it is for the indicator, the fit and
        the shapes).
    n_modes : int, optional
        Keep the `n_modes` most prominent peaks (then sorted by frequency); default all peaks above
        `prominence`. A warning is issued if fewer are found.
    fmin, fmax : float, optional
        Frequency band in Hz (default the whole axis above 0 Hz).
    min_coherence : float, optional
        Smallest mean coherence (over outputs) near a peak (median within ±3 bins, since leakage
        dips the coherence at a lightly damped resonance); default 0.8 (keeps noise peaks of
        badly excited bands out; lower it for noisy but genuine resonances).
    prominence : float, optional
        Smallest peak prominence of the indicator in dB; default 3 dB (the half-power level).
    refine : {'sdof', None}, optional
        Refine frequency and damping by the single-DOF fit (default) or keep the half-power values.
    input : int or str, optional
        Input column used for the shapes; default the input with the largest quadrature response
        at each peak.

    Returns
    -------
    ModalModel
        ``method='peak_picking'``; points are the FRF outputs. ``extra`` holds per-mode arrays
        ``"frequency_peak"`` (Hz), ``"damping_half_power"``, ``"peak_value"`` (indicator, dB),
        ``"prominence"`` (dB), ``"fit_residual"`` (relative), ``"residue_shapes"`` (complex
        (n_modes, n_points), shapes from the fitted modal constants), ``"mpc"``, and the settings.

    Raises
    ------
    ValueError
        If the band holds fewer than 5 bins, `refine` is not allowed, or `input` is unknown.

    Notes
    -----
    Peak picking assumes well separated, lightly damped modes; for close modes the quadrature
    shapes mix and the half-power width is undefined (NaN, then the SDOF fit starts from 1 %).
    The half-power width needs several bins across it: resolution Δf ≲ ζ fn / 2.

    References
    ----------
    .. [1] D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research
       Studies Press, 2000, ch. 4 (SDOF modal analysis methods: peak-amplitude, circle-fit,
       inverse/line-fit).

    Examples
    --------
    The accelerance of 1 kg on 1e4 N/m with 2 % damping: 15.92 Hz and ζ = 0.02 are recovered.

    >>> import numpy as np
    >>> from vibroscope.spectral import FRF
    >>> f = np.arange(0.0, 40.0, 0.01)
    >>> w, wn = 2 * np.pi * f, np.sqrt(1e4)
    >>> H = (-w**2 / (1e4 - w**2 + 2j * 0.02 * wn * w))[:, None, None]
    >>> frf = FRF(f, H, np.ones((f.size, 1)), ["force"], ["acc"], "analytic", "accelerance")
    >>> m = peak_picking(frf)
    >>> print(f"{m.natural_frequencies[0]:.2f} Hz, zeta = {m.damping_ratios[0]:.4f}")
    15.92 Hz, zeta = 0.0200
    """
    check_option("refine", refine, ("sdof", None))
    f_all = frf.frequencies
    if frf.kind is not None and frf.kind != "receptance":
        rec = frf.to("receptance").H
    else:
        rec = np.asarray(frf.H)
    acc = frf.to("accelerance").H if frf.kind not in (None, "accelerance") else np.asarray(frf.H)
    mob = frf.to("mobility").H if frf.kind not in (None, "mobility") else np.asarray(frf.H)
    band = f_all > 0
    if fmin is not None:
        band &= f_all >= fmin
    if fmax is not None:
        band &= f_all <= fmax
    idx = np.flatnonzero(band)
    if idx.size < 5:
        raise ValueError(f"the band {fmin=} .. {fmax=} Hz holds {idx.size} bins; at least 5 are needed")
    f = f_all[idx]
    R = rec[idx]  # (n_f, n_out, n_in)
    Aacc = acc[idx]
    n_f, n_out, n_in = R.shape
    # plain power sum: all responses share one unit, and the mobility's roll-off on both sides
    # keeps noise far from the modes low (a per-channel median normalisation lifts it instead)
    P = np.abs(mob[idx]) ** 2
    ind = np.nan_to_num(np.mean(P.reshape(n_f, -1), axis=1), nan=0.0)
    ind_db = 10 * np.log10(np.maximum(ind, np.finfo(float).tiny))
    coh = np.asarray(frf.coherence)[idx]
    coh_mean = np.nanmean(coh, axis=1) if coh.size else np.ones(n_f)
    peaks, props = scipy.signal.find_peaks(ind_db, prominence=prominence)
    prom = props["prominences"]
    # leakage dips the coherence right at a lightly damped resonance (one or two bins): judge a
    # peak by the median coherence within ±3 bins, low all around a noise peak
    coh_near = scipy.ndimage.median_filter(np.nan_to_num(coh_mean, nan=1.0), size=7, mode="nearest")
    ok = coh_near[peaks] >= min_coherence
    peaks, prom = peaks[ok], prom[ok]
    if n_modes is not None:
        if len(peaks) < n_modes:
            warnings.warn(f"found {len(peaks)} peaks above {prominence=} dB, fewer than {n_modes=}", stacklevel=2)
        best = np.sort(np.argsort(prom)[::-1][:n_modes])
        peaks, prom = peaks[best], prom[best]

    if input is None:
        in_cols = None
    elif isinstance(input, str):
        if input not in frf.inputs:
            raise ValueError(f"{input=} is not one of the inputs {frf.inputs}")
        in_cols = frf.inputs.index(input)
    else:
        in_cols = int(input)

    df = f[1] - f[0]
    fn_l, z_l, shapes, res_shapes, fpk, zhp, pkv, fitres = [], [], [], [], [], [], [], []
    for k, pr in zip(peaks, prom):
        f_peak = _parabolic_peak(f, ind_db, k)
        f1, f2 = half_power_bandwidth(f, ind, k)
        z_hp = (f2 - f1) / (2 * f_peak) if np.isfinite(f1) and np.isfinite(f2) else np.nan
        fn, zeta = f_peak, z_hp
        fitted_A = None
        resid = np.nan
        if refine == "sdof":
            bw = (f2 - f1) if np.isfinite(z_hp) else 2 * 0.01 * f_peak
            half = max(1.0 * bw, 4 * df)
            sel = (f >= f_peak - half) & (f <= f_peak + half)
            if np.count_nonzero(sel) >= 5:
                z0 = z_hp if np.isfinite(z_hp) and z_hp > 0 else 0.01
                try:
                    fn_fit, z_fit, A, resid = fit_sdof(f[sel], R[sel].reshape(np.count_nonzero(sel), -1), f_peak, z0)
                    if f[sel][0] < fn_fit < f[sel][-1] and 0 < z_fit < 0.49:
                        fn, zeta = fn_fit, z_fit
                        fitted_A = A.reshape(n_out, n_in)
                except (np.linalg.LinAlgError, ValueError):
                    pass
        kk = int(np.argmin(np.abs(f - fn)))
        q = np.imag(Aacc[kk])  # (n_out, n_in)
        col = int(np.argmax(np.sum(q**2, axis=0))) if in_cols is None else in_cols
        shapes.append(q[:, col].astype(complex))
        res_shapes.append(fitted_A[:, col] if fitted_A is not None else np.full(n_out, np.nan + 0j))
        fn_l.append(fn)
        z_l.append(zeta)
        fpk.append(f_peak)
        zhp.append(z_hp)
        pkv.append(ind_db[k])
        fitres.append(resid)
    shapes_arr = normalize_shapes(np.array(shapes).reshape(len(shapes), n_out))
    res_arr = normalize_shapes(np.array(res_shapes).reshape(len(res_shapes), n_out))
    extra = {
        "frequency_peak": np.array(fpk),
        "damping_half_power": np.array(zhp),
        "peak_value": np.array(pkv),
        "prominence": np.asarray(prom, dtype=float),
        "fit_residual": np.array(fitres),
        "residue_shapes": res_arr,
        "mpc": mpc(shapes_arr) if len(shapes) else np.zeros(0),
        "settings": dict(fmin=fmin, fmax=fmax, min_coherence=min_coherence, prominence=prominence,
                         refine=refine, frf_kind=frf.kind, estimator=frf.estimator),
    }
    return ModalModel(np.array(fn_l), np.array(z_l), shapes_arr, frf.outputs, "peak_picking", extra)
