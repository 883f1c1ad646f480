"""Peak picking on measured FRFs: natural frequencies, half-power damping refined by a single-DOF
fit, and mode shapes by quadrature picking (Ewins 2000, ch. 4)."""

from __future__ import annotations

import warnings
from typing import Literal

import numpy as np
import scipy.optimize
import scipy.ndimage
import scipy.signal

from vibroscope._checks import check_option
from vibroscope.modal._peaks import band_indices, parabolic_peak
from vibroscope.modal._results import ModalModel, mpc, normalize_shapes
from vibroscope.spectral import FRF

__all__ = ["peak_picking", "half_power_bandwidth", "fit_sdof"]


def half_power_bandwidth(frequencies: np.ndarray, power: np.ndarray, k: int) -> tuple[float, float]:
    """Half-power (−3 dB) frequencies around the peak bin `k` of a power-like curve.

    Walks left and right from `k` until `power` falls below ``power[k] / 2`` and interpolates the
    crossings linearly in dB between the two bins that bracket them.

    Parameters
    ----------
    frequencies : ndarray, shape (n_f,)
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
                return float(frequencies[j] + t * (frequencies[nxt] - frequencies[j]))
            if power[nxt] > power[k]:
                return np.nan
            j = nxt
        return np.nan

    return walk(-1), walk(+1)


def fit_sdof(frequencies: np.ndarray, H: np.ndarray, fn0: float,
             zeta0: float) -> tuple[float, float, np.ndarray, float]:
    """Least-squares single-DOF fit of receptances around one resonance, all channels together.

    Each column ``k`` of `H` is modelled as ``A_k / (ωr² − ω² + 2jζωrω) + R_k + M_k / ω²`` with a
    complex modal constant ``A_k`` and the complex upper (stiffness-like, ``R_k``) and lower
    (mass-like, ``M_k / ω²``) residuals standing for the out-of-band modes (Ewins 2000,
    ch. 4: the SDOF methods and residual terms). ``A``, ``R`` and ``M`` enter linearly and are eliminated (variable
    projection); ``(fr, ζ)`` are found by :func:`scipy.optimize.least_squares`. Columns are weighted
    to equal peak magnitude.

    Parameters
    ----------
    frequencies : ndarray, shape (n_f,)
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
    w = 2 * np.pi * np.asarray(frequencies, dtype=float)
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

    lo = [frequencies[0], 1e-6]
    hi = [frequencies[-1], 0.5]
    p0 = [float(np.clip(fn0, frequencies[0] + 1e-9, frequencies[-1] - 1e-9)), float(np.clip(zeta0, 2e-6, 0.49))]
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

    See Also
    --------
    lscf : All modes of a band at once, close modes included (LSCF/polyMAX).
    fdd : The output-only counterpart on a cross-spectral matrix.

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
    >>> frf = FRF(frequencies=f, H=H, coherence=np.ones((f.size, 1)), inputs=["force"], outputs=["acc"],
    ...           estimator="analytic", kind="accelerance")
    >>> m = peak_picking(frf)
    >>> print(f"{m.natural_frequencies[0]:.2f} Hz, zeta = {m.damping_ratios[0]:.4f}")
    15.92 Hz, zeta = 0.0200
    """
    check_option("refine", refine, ("sdof", None))
    rec, acc, mob = _as_kind(frf, "receptance"), _as_kind(frf, "accelerance"), _as_kind(frf, "mobility")
    idx = band_indices(frf.frequencies, fmin, fmax)
    f = frf.frequencies[idx]
    R, Aacc = rec[idx], acc[idx]  # (n_f, n_out, n_in)
    n_f, n_out, n_in = R.shape
    # plain power sum: all responses share one unit, and the mobility's roll-off on both sides
    # keeps noise far from the modes low (a per-channel median normalisation lifts it instead)
    ind = np.nan_to_num(np.mean((np.abs(mob[idx]) ** 2).reshape(n_f, -1), axis=1), nan=0.0)
    ind_db = 10 * np.log10(np.maximum(ind, np.finfo(float).tiny))
    peaks, prom = _coherent_peaks(ind_db, np.asarray(frf.coherence)[idx], prominence, min_coherence)
    if n_modes is not None:
        if len(peaks) < n_modes:
            warnings.warn(f"found {len(peaks)} peaks above {prominence=} dB, fewer than {n_modes=}", stacklevel=2)
        best = np.sort(np.argsort(prom)[::-1][:n_modes])
        peaks, prom = peaks[best], prom[best]
    in_col = _input_column(frf, input)
    rows = []
    for k in peaks:
        row = _fit_peak(f, ind, ind_db, int(k), R, refine)
        # quadrature picking: Im of the accelerance at the natural frequency, sign kept
        q = np.imag(Aacc[int(np.argmin(np.abs(f - row["fn"])))])  # (n_out, n_in)
        col = int(np.argmax(np.sum(q**2, axis=0))) if in_col is None else in_col
        row["shape"] = q[:, col].astype(complex)
        A = row.pop("A")
        row["residue_shape"] = A.reshape(n_out, n_in)[:, col] if A is not None else np.full(n_out, np.nan + 0j)
        rows.append(row)

    def column(key, dtype=float):
        return np.array([r[key] for r in rows], dtype=dtype)

    shapes = normalize_shapes(column("shape", complex).reshape(len(rows), n_out))
    extra = {
        "frequency_peak": column("frequency_peak"),
        "damping_half_power": column("damping_half_power"),
        "peak_value": column("peak_value"),
        "prominence": np.asarray(prom, dtype=float),
        "fit_residual": column("fit_residual"),
        "residue_shapes": normalize_shapes(column("residue_shape", complex).reshape(len(rows), n_out)),
        "mpc": mpc(shapes) if len(rows) else np.zeros(0),
        "settings": dict(fmin=fmin, fmax=fmax, min_coherence=min_coherence, prominence=prominence,
                         refine=refine, frf_kind=frf.kind, estimator=frf.estimator),
    }
    return ModalModel(natural_frequencies=column("fn"), damping_ratios=column("zeta"), shapes=shapes,
                      points=frf.outputs, method="peak_picking", extra=extra)


def _as_kind(frf: FRF, kind: str) -> np.ndarray:
    """``H`` as `kind` (converted with :meth:`FRF.to`); as it is when the FRF's kind is unknown."""
    return frf.to(kind).H if frf.kind not in (None, kind) else np.asarray(frf.H)


def _coherent_peaks(ind_db: np.ndarray, coh: np.ndarray, prominence: float,
                    min_coherence: float) -> tuple[np.ndarray, np.ndarray]:
    """Peaks of the indicator (dB) with their prominences, where the coherence near them reaches
    `min_coherence`."""
    coh_mean = np.nanmean(coh, axis=1) if coh.size else np.ones(len(ind_db))
    peaks, props = scipy.signal.find_peaks(ind_db, prominence=prominence)
    # leakage dips the coherence right at a lightly damped resonance (one or two bins): judge a
    # peak by the median coherence within ±3 bins, low all around a noise peak
    coh_near = scipy.ndimage.median_filter(np.nan_to_num(coh_mean, nan=1.0), size=7, mode="nearest")
    ok = coh_near[peaks] >= min_coherence
    return peaks[ok], props["prominences"][ok]


def _input_column(frf: FRF, input: int | str | None) -> int | None:
    """Index of the input used for the shapes (None: the strongest at each peak)."""
    if input is None:
        return None
    if isinstance(input, str):
        if input not in frf.inputs:
            raise ValueError(f"{input=} is not one of the inputs {frf.inputs}")
        return frf.inputs.index(input)
    return int(input)


def _fit_peak(f: np.ndarray, ind: np.ndarray, ind_db: np.ndarray, k: int, R: np.ndarray, refine) -> dict:
    """Frequency and damping of the peak at bin `k`: parabolic peak and half-power width, then the
    single-DOF fit of the receptances `R` over ``fn ± (f2 − f1)`` (at least ± 4 bins) when
    ``refine='sdof'`` and the fit lands inside that band. ``"A"``: the fitted modal constants or None."""
    f_peak = parabolic_peak(f, ind_db, k)
    f1, f2 = half_power_bandwidth(f, ind, k)
    z_hp = (f2 - f1) / (2 * f_peak) if np.isfinite(f1) and np.isfinite(f2) else np.nan
    fn, zeta, A, resid = f_peak, z_hp, None, np.nan
    if refine == "sdof":
        bw = (f2 - f1) if np.isfinite(z_hp) else 2 * 0.01 * f_peak
        half = max(1.0 * bw, 4 * (f[1] - f[0]))
        sel = (f >= f_peak - half) & (f <= f_peak + half)
        if np.count_nonzero(sel) >= 5:
            z0 = z_hp if np.isfinite(z_hp) and z_hp > 0 else 0.01
            try:
                fn_fit, z_fit, A_fit, resid = fit_sdof(f[sel], R[sel].reshape(np.count_nonzero(sel), -1), f_peak, z0)
                if f[sel][0] < fn_fit < f[sel][-1] and 0 < z_fit < 0.49:
                    fn, zeta, A = fn_fit, z_fit, A_fit
            except (np.linalg.LinAlgError, ValueError):
                pass
    return {"fn": fn, "zeta": zeta, "frequency_peak": f_peak, "damping_half_power": z_hp,
            "peak_value": ind_db[k], "fit_residual": resid, "A": A}
