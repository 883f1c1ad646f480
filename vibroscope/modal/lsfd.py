"""Least-squares frequency-domain (LSFD) estimation of residues, residuals and mode shapes from
known poles, and its result :class:`LSFDResult`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.linalg

from vibroscope._checks import read_only
from vibroscope.modal._results import ModalModel, mpc, normalize_shapes
from vibroscope.spectral import FRF
from vibroscope.spectral.kinds import power_of_jw

__all__ = ["pole_residue_form", "lsfd", "LSFDResult"]


def fit_band(frf: FRF, fmin: float | None, fmax: float | None) -> tuple[np.ndarray, float, float]:
    """Mask of the FRF lines used: ``fmin <= f <= fmax``, ``f > 0`` and all of ``H`` finite."""
    f = frf.frequencies
    pos = f > 0
    if not pos.any():
        raise ValueError("the FRF has no line above 0 Hz")
    lo = float(f[pos].min()) if fmin is None else float(fmin)
    hi = float(f.max()) if fmax is None else float(fmax)
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo >= hi:
        raise ValueError(f"fmin={lo} must be below fmax={hi} (Hz)")
    sel = pos & (f >= lo) & (f <= hi) & np.all(np.isfinite(frf.H), axis=(1, 2))
    return sel, lo, hi


def _poles(natural_frequencies: np.ndarray, damping_ratios: np.ndarray) -> np.ndarray:
    """``λ = −ζ ω_n + j ω_n sqrt(1 − ζ²)`` (rad/s) from natural frequencies (Hz) and damping."""
    wn = 2 * np.pi * np.asarray(natural_frequencies, float)
    z = np.asarray(damping_ratios, float)
    return -z * wn + 1j * wn * np.sqrt(1 - z**2)


def _basis(w: np.ndarray, poles: np.ndarray, power: int, residuals: bool) -> np.ndarray:
    """Complex columns ``Φ`` (n_f, 2 n_modes [+ 4]) whose real coefficients give the model.

    For each pole, with ``a = (jω)^p/(jω−λ)`` and ``b = (jω)^p/(jω−λ*)``, the pair ``a + b``
    (coefficient Re ρ) and ``j (a − b)`` (coefficient Im ρ) of the receptance residue ``ρ``;
    then ``(jω)^(p−2)``, ``j (jω)^(p−2)``, ``(jω)^p``, ``j (jω)^p`` for the complex lower and
    upper residuals.
    """
    jw = 1j * w[:, None]
    s = jw**power
    a = s / (jw - poles[None, :])
    b = s / (jw - np.conj(poles)[None, :])
    cols = [a + b, 1j * (a - b)]
    if residuals:
        lo = jw ** (power - 2)
        up = jw**power
        cols += [lo, 1j * lo, up, 1j * up]
    return np.concatenate(cols, axis=1)


def fit_residues(w: np.ndarray, H: np.ndarray, poles: np.ndarray, power: int, residuals: bool,
         fast: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Real-valued least squares of residues (and residuals) for given poles.

    Parameters
    ----------
    w : ndarray, shape (n_f,)
        Angular frequencies in rad/s.
    H : ndarray, complex, shape (n_f, n_outputs, n_inputs)
    poles : ndarray, complex, shape (n_modes,)
    power : int
        Power of jω of the FRF kind (0 receptance, 1 mobility, 2 accelerance).
    residuals : bool
        Fit the lower and upper residuals.
    fast : bool
        Solve the slightly regularised normal equations by Cholesky instead of ``lstsq``:
        quicker, less accurate (used for the stabilization diagram's shapes).

    Returns
    -------
    residues : ndarray, complex, shape (n_modes, n_outputs, n_inputs)
        Residues of `H` at the poles, ``λ^p ρ``.
    lower, upper : ndarray, complex, shape (n_outputs, n_inputs)
    """
    nf, no, ni = H.shape
    n = len(poles)
    Phi = _basis(w, poles, power, residuals)
    A = np.concatenate([Phi.real, Phi.imag], axis=0)
    B = np.concatenate([H.real, H.imag], axis=0).reshape(2 * nf, no * ni)
    norm = np.linalg.norm(A, axis=0)
    norm[norm == 0] = 1.0
    A = A / norm
    if fast:
        G = A.T @ A  # unit diagonal
        G[np.diag_indices_from(G)] += 1e-10
        try:
            x = scipy.linalg.cho_solve(scipy.linalg.cho_factor(G, check_finite=False), A.T @ B,
                                       check_finite=False)
        except np.linalg.LinAlgError:
            x = np.linalg.lstsq(A, B, rcond=None)[0]
    else:
        x = np.linalg.lstsq(A, B, rcond=None)[0]
    x = (x / norm[:, None]).reshape(-1, no, ni)
    R = (x[:n] + 1j * x[n : 2 * n]) * (poles**power)[:, None, None]
    if residuals:
        lower = x[2 * n] + 1j * x[2 * n + 1]
        upper = x[2 * n + 2] + 1j * x[2 * n + 3]
    else:
        lower = upper = np.zeros((no, ni), complex)
    return R, lower, upper


def _resolve_driving_point(dp, outputs: Sequence[str], inputs: Sequence[str]) -> tuple[int, int] | None:
    """``(output index, input index)`` from indices or names; a single value names the output
    (the input then is the only one)."""
    if dp is None:
        return None
    if isinstance(dp, (tuple, list)):
        if len(dp) != 2:
            raise ValueError(f"driving_point={dp!r} must be (output, input)")
        o, i = dp
    else:
        if len(inputs) != 1:
            raise ValueError(f"driving_point={dp!r} must be (output, input) with {len(inputs)} inputs")
        o, i = dp, 0

    def index(x, names, what):
        if isinstance(x, (int, np.integer)):
            if not -len(names) <= x < len(names):
                raise ValueError(f"driving-point {what} index {x} out of range for {len(names)} {what}s")
            return int(x) % len(names)
        try:
            return list(names).index(x)
        except ValueError:
            raise ValueError(f"no {what} {x!r}; {what}s are {list(names)}") from None

    return index(o, outputs, "output"), index(i, inputs, "input")


@dataclass(frozen=True, eq=False, kw_only=True)
class LSFDResult:
    """Residues and residuals of a pole-residue model fitted to an FRF (:func:`lsfd`).

    The model, per output ``o`` and input ``i``::

        H(jω) = Σ_r [(jω/λ_r)^p R_r/(jω − λ_r) + (jω/λ_r*)^p R_r*/(jω − λ_r*)]
                + LR (jω)^(p−2) + UR (jω)^p

    with ``p`` = 0 (receptance or unknown kind), 1 (mobility), 2 (accelerance): ``(jω)^p`` times
    a receptance in pole-residue form, ``R_r`` being the residue of ``H`` at ``λ_r``.

    Attributes
    ----------
    natural_frequencies : ndarray, shape (n_modes,)
        Natural frequencies in Hz (ascending).
    damping_ratios : ndarray, shape (n_modes,)
        Viscous damping ratios (dimensionless).
    poles : ndarray, complex, shape (n_modes,)
        ``λ_r = −ζ ω_n + j ω_n sqrt(1 − ζ²)`` in rad/s.
    residues : ndarray, complex, shape (n_modes, n_outputs, n_inputs)
        ``R_r``, the residues of ``H`` at the poles, in the FRF's units times rad/s
        (``R_r / λ_r^p`` are the receptance residues).
    lower_residual, upper_residual : ndarray, complex, shape (n_outputs, n_inputs)
        Coefficients of ``(jω)^(p−2)`` (modes below the band: mass line) and ``(jω)^p`` (modes
        above the band: stiffness line); zero when not fitted.
    outputs, inputs : tuple of str
        Channel names.
    kind : {'accelerance', 'mobility', 'receptance'} or None
        FRF kind the residues belong to.
    fmin, fmax : float
        Frequency band of the fit in Hz.
    frequencies : ndarray, shape (n_f,)
        The FRF lines used in the fit (Hz).
    units : str
        Units of the FRF.
    driving_point : tuple of int or None
        ``(output index, input index)`` of a co-located response and force, used for unit
        modal mass scaling.
    residuals : bool
        Whether the residuals were fitted.
    """

    natural_frequencies: np.ndarray
    damping_ratios: np.ndarray
    poles: np.ndarray
    residues: np.ndarray
    lower_residual: np.ndarray
    upper_residual: np.ndarray
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    kind: str | None
    fmin: float
    fmax: float
    frequencies: np.ndarray = field(default_factory=lambda: np.zeros(0))
    units: str = ""
    driving_point: tuple[int, int] | None = None
    residuals: bool = True

    def __post_init__(self) -> None:
        for name, dt in (("natural_frequencies", float), ("damping_ratios", float), ("poles", complex),
                         ("residues", complex), ("lower_residual", complex), ("upper_residual", complex),
                         ("frequencies", float)):
            object.__setattr__(self, name, read_only(getattr(self, name), dt))
        object.__setattr__(self, "outputs", tuple(self.outputs))
        object.__setattr__(self, "inputs", tuple(self.inputs))

    def __len__(self) -> int:
        return int(self.poles.size)

    def __repr__(self) -> str:
        fs = ", ".join(f"{f:.4g}" for f in self.natural_frequencies[:6])
        more = ", ..." if len(self) > 6 else ""
        return (f"LSFDResult({len(self)} modes, f = [{fs}{more}] Hz, {len(self.outputs)} outputs × "
                f"{len(self.inputs)} inputs, {self.fmin:.4g}–{self.fmax:.4g} Hz, kind={self.kind!r})")

    @property
    def power(self) -> int:
        """Power of jω of the FRF kind: 0 receptance (or unknown), 1 mobility, 2 accelerance."""
        return power_of_jw(self.kind)

    def synthesize(self, frequencies=None) -> FRF:
        """The fitted model evaluated on a frequency axis.

        Parameters
        ----------
        frequencies : array_like, shape (n_f,), optional
            Frequencies in Hz; default the lines of the fit. A 0 Hz line is NaN when the lower
            residual's power ``p − 2`` is negative.

        Returns
        -------
        FRF
            ``estimator='lsfd'``, the same kind and units, NaN coherence.
        """
        f = self.frequencies if frequencies is None else np.atleast_1d(np.asarray(frequencies, float))
        w = 2 * np.pi * f
        jw = 1j * w[:, None, None]
        lam = self.poles[:, None, None]
        H = np.zeros((len(f),) + self.residues.shape[1:], complex)
        rho = self.residues / (self.poles**self.power)[:, None, None]  # receptance residues
        for r in range(len(self)):  # modes one by one: (n_f, n_out, n_in) at a time
            H += rho[r] / (jw - lam[r]) + np.conj(rho[r]) / (jw - np.conj(lam[r]))
        H *= jw**self.power
        if self.residuals:
            with np.errstate(divide="ignore", invalid="ignore"):
                H = H + self.lower_residual * jw ** (self.power - 2) + self.upper_residual * jw**self.power
        coh = np.full((len(f), len(self.outputs)), np.nan)
        return FRF(frequencies=f, H=H, coherence=coh, inputs=self.inputs, outputs=self.outputs, estimator="lsfd",
                   kind=self.kind, units=self.units,
                   settings=dict(fmin=self.fmin, fmax=self.fmax, residuals=self.residuals))

    def peak_magnitude(self) -> np.ndarray:
        """Modulus of each mode's own term at its resonance, at the output/input pair where it is
        largest (units of the FRF): the height of the mode's peak.

        Returns
        -------
        ndarray, shape (n_modes,)
        """
        rho = self.residues / (self.poles**self.power)[:, None, None]
        jw = 2j * np.pi * self.natural_frequencies[:, None, None]
        lam = self.poles[:, None, None]
        t = (rho / (jw - lam) + np.conj(rho) / (jw - np.conj(lam))) * jw**self.power
        return np.abs(t).reshape(len(self), -1).max(axis=1) if len(self) else np.zeros(0)

    def dominance(self) -> np.ndarray:
        """How much each mode stands out at its own resonance.

        For mode ``r`` at ``f_r``: ``|H_r| / |H − H_r|``, the modulus of the mode's own term over
        that of everything else (the other modes and the residuals), taken at the output/input
        pair where it is largest. A mode whose term is well below the rest everywhere is not seen
        in the measurement (a computational or a barely excited pole); two equal modes one
        half-power bandwidth apart score about 2 each.

        Returns
        -------
        ndarray, shape (n_modes,)
            Dimensionless ratios ≥ 0.
        """
        out = np.zeros(len(self))
        rho = self.residues / (self.poles**self.power)[:, None, None]
        for r in range(len(self)):
            jw = 2j * np.pi * self.natural_frequencies[r]
            terms = (rho / (jw - self.poles[:, None, None]) + np.conj(rho) / (jw - np.conj(self.poles)[:, None, None]))
            terms = terms * jw**self.power
            rest = terms.sum(axis=0) - terms[r]
            if self.residuals:
                rest = rest + self.lower_residual * jw ** (self.power - 2) + self.upper_residual * jw**self.power
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.abs(terms[r]) / np.abs(rest)
            out[r] = float(np.nanmax(ratio)) if np.any(np.isfinite(ratio)) else np.inf
        return out

    def error(self, frf: FRF) -> np.ndarray:
        """Relative misfit of the model to an FRF over the fitted band.

        Parameters
        ----------
        frf : FRF
            Measured FRF with the same outputs and inputs (its lines in ``[fmin, fmax]`` above
            0 Hz are compared).

        Returns
        -------
        ndarray, shape (n_outputs,)
            ``‖H − Ĥ‖ / ‖H‖`` per output, over the lines and inputs (dimensionless).

        Raises
        ------
        ValueError
            If `frf` has other numbers of outputs or inputs.
        """
        if frf.H.shape[1:] != self.residues.shape[1:]:
            raise ValueError(f"FRF of shape {frf.H.shape[1:]} (outputs, inputs) for a model of "
                             f"{self.residues.shape[1:]}")
        sel, _, _ = fit_band(frf, self.fmin, self.fmax)
        H = frf.H[sel]
        Hs = self.synthesize(frf.frequencies[sel]).H
        return np.sqrt(np.sum(np.abs(H - Hs) ** 2, axis=(0, 2)) / np.sum(np.abs(H) ** 2, axis=(0, 2)))

    def modal_model(self, driving_point=None) -> ModalModel:
        """Mode shapes from the residues.

        With a driving point (output ``k`` co-located with input ``i``) the residues are turned
        into receptance residues ``R_r / λ_r^p`` and scaled to unit modal mass: for a
        proportionally damped system ``R_r = φ_r φ_rᵀ / (2 j ω_d m_r)``, so with ``m_r = 1``
        ``φ_k = sqrt(2 j ω_d R_kk)`` and ``φ_j = 2 j ω_d R_jk / φ_k`` (ω_d = Im λ_r; the sign is
        chosen so the largest entry has a positive real part). Without one, each shape is the
        residue column of the input with the largest norm, scaled to unit maximum modulus.

        Parameters
        ----------
        driving_point : int, str or (output, input), optional
            Output (and input) index or name of the driving point; default the one given to
            :func:`lsfd`, else an output whose name equals an input's name, else none.

        Returns
        -------
        ModalModel
            ``method='lscf'``; ``extra["normalisation"]`` (``"unit_modal_mass"`` or
            ``"unit_maximum"``), ``extra["mpc"]``, ``extra["reference_input"]`` (input index per
            mode) and ``extra["driving_point"]``.

        Raises
        ------
        ValueError
            If the driving point names an unknown output or input.
        """
        dp = _resolve_driving_point(driving_point, self.outputs, self.inputs)
        if dp is None:
            dp = self.driving_point
        if dp is None:
            common = [o for o in self.outputs if o in self.inputs]
            if common:
                dp = (self.outputs.index(common[0]), self.inputs.index(common[0]))
        n, no, ni = self.residues.shape
        if dp is not None:
            k, i = dp
            Rrec = self.residues[:, :, i] / (self.poles[:, None] ** self.power)
            wd2j = 2j * self.poles.imag[:, None]
            phik = np.sqrt(wd2j[:, 0] * Rrec[:, k])
            with np.errstate(divide="ignore", invalid="ignore"):
                shapes = wd2j * Rrec / phik[:, None]
            for r in range(n):
                j = int(np.argmax(np.abs(shapes[r])))
                if shapes[r, j].real < 0:
                    shapes[r] = -shapes[r]
            ref = np.full(n, i)
            norm = "unit_modal_mass"
        else:
            ref = np.argmax(np.linalg.norm(self.residues, axis=1), axis=1) if n else np.zeros(0, int)
            shapes = (normalize_shapes(self.residues[np.arange(n), :, ref]) if n
                      else np.zeros((0, no), complex))
            norm = "unit_maximum"
        return ModalModel(natural_frequencies=self.natural_frequencies, damping_ratios=self.damping_ratios,
                          shapes=shapes, points=self.outputs, method="lscf",
                          extra={"normalisation": norm, "mpc": mpc(shapes) if n else np.zeros(0),
                                 "reference_input": np.asarray(ref, int), "driving_point": dp,
                                 "settings": dict(fmin=self.fmin, fmax=self.fmax, residuals=self.residuals,
                                                  kind=self.kind)})


def lsfd(
    frf: FRF,
    natural_frequencies,
    damping_ratios,
    *,
    fmin: float | None = None,
    fmax: float | None = None,
    residuals: bool = True,
    driving_point=None,
) -> LSFDResult:
    """Least-squares frequency-domain estimation of residues for given poles.

    Every FRF ``H_oi`` is fitted, as one real-valued linear least-squares problem (real and
    imaginary parts stacked, columns scaled to unit norm), by::

        H(jω) = Σ_r [(jω/λ_r)^p R_r/(jω − λ_r) + (jω/λ_r*)^p R_r*/(jω − λ_r*)]
                + LR (jω)^(p−2) + UR (jω)^p

    with ``λ_r = −ζ_r ω_r + j ω_r sqrt(1 − ζ_r²)`` and ``p`` = 0 for a receptance (or unknown
    kind), 1 for a mobility, 2 for an accelerance: the lower residual ``LR`` is the mass line
    of the modes below the band, the upper residual ``UR`` the stiffness line of those above.
    ``R_r`` is the residue of ``H`` at ``λ_r``.

    See Also
    --------
    lscf : The poles this fit takes.
    auto_lscf : LSCF, automatic pole selection and this fit in one call.

    Notes
    -----
    The modal terms are those of a receptance, ``ρ_r/(jω − λ_r) + c.c.`` with ``ρ_r = R_r/λ_r^p``,
    times ``(jω)^p`` (as in sdypy-EMA's LSFD). A plain pole-residue term of an accelerance,
    ``R_r/(jω − λ_r) + c.c.``, lacks the constant ``−2 Re(λ_r ρ_r)`` (the mode's own mass line
    ``φφᵀ/m_r``), so a mode below the band would leave a ``(ω_r/ω)²`` tail that the constant
    lower residual cannot absorb; with the ``(jω)^p`` factor each term is the whole modal
    contribution and the residuals are exactly the leading terms of the modes outside the band.

    Parameters
    ----------
    frf : FRF
        Measured FRF ``H[f, output, input]``; its ``kind`` selects ``p``.
    natural_frequencies : array_like, shape (n_modes,)
        Natural frequencies of the poles in Hz (e.g. from :func:`vibroscope.modal.lscf`).
    damping_ratios : array_like, shape (n_modes,)
        Their damping ratios, in [0, 1).
    fmin, fmax : float, optional
        Frequency band of the fit in Hz; default all lines above 0 Hz.
    residuals : bool, optional
        Fit the complex lower and upper residuals (default True).
    driving_point : int, str or (output, input), optional
        Co-located output and input (indices or names) for unit modal mass scaling in
        :meth:`LSFDResult.modal_model`.

    Returns
    -------
    LSFDResult
        Residues ``(n_modes, n_outputs, n_inputs)``, residuals, and the band.

    Raises
    ------
    ValueError
        If the frequencies and damping ratios differ in length or are out of range, the band
        is empty or holds fewer lines than unknowns, or the driving point is unknown.

    References
    ----------
    .. [1] W. Heylen, S. Lammens and P. Sas, *Modal Analysis Theory and Testing*, KU Leuven,
       1997, §A.6 (LSFD, residual terms).
    .. [2] B. Peeters, H. Van der Auweraer, P. Guillaume and J. Leuridan, "The PolyMAX
       frequency-domain method: a new standard for modal parameter estimation?", Shock and
       Vibration 11, 395–409, 2004.

    Examples
    --------
    >>> import numpy as np
    >>> from vibroscope.models import LumpedModel
    >>> from vibroscope.spectral import FRF
    >>> model = LumpedModel.chain([1.0], [1e4], [2.0])
    >>> f = np.linspace(1, 50, 500)
    >>> h = FRF(frequencies=f, H=model.frf(f), coherence=np.ones((500, 1)), inputs=["u"], outputs=["y"],
    ...         estimator="analytic", kind="accelerance")
    >>> md = model.modes()
    >>> res = lsfd(h, md.natural_frequencies, md.damping_ratios)
    >>> bool(res.error(h)[0] < 1e-9)
    True
    """
    fn = np.atleast_1d(np.asarray(natural_frequencies, float))
    zeta = np.atleast_1d(np.asarray(damping_ratios, float))
    if fn.ndim != 1 or fn.shape != zeta.shape:
        raise ValueError(f"{fn.shape=} natural frequencies and {zeta.shape=} damping ratios must match")
    if np.any(~np.isfinite(fn)) or np.any(fn <= 0) or np.any(~(zeta >= 0)) or np.any(zeta >= 1):
        raise ValueError("natural frequencies must be positive (Hz) and damping ratios in [0, 1)")
    order = np.argsort(fn)
    fn, zeta = fn[order], zeta[order]
    sel, lo, hi = fit_band(frf, fmin, fmax)
    f = frf.frequencies[sel]
    n_unknown = 2 * len(fn) + (4 if residuals else 0)
    if 2 * len(f) < n_unknown:
        raise ValueError(f"{len(f)} lines in [{lo}, {hi}] Hz are too few for {n_unknown} real unknowns")
    lam = _poles(fn, zeta)
    power = power_of_jw(frf.kind)
    R, LR, UR = fit_residues(2 * np.pi * f, frf.H[sel], lam, power, residuals)
    dp = _resolve_driving_point(driving_point, frf.outputs, frf.inputs)
    return LSFDResult(natural_frequencies=fn, damping_ratios=zeta, poles=lam, residues=R, lower_residual=LR,
                      upper_residual=UR, outputs=frf.outputs, inputs=frf.inputs, kind=frf.kind, fmin=lo, fmax=hi,
                      frequencies=f, units=frf.units, driving_point=dp, residuals=bool(residuals))


def pole_residue_form(frf: FRF, result: "LSFDResult") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Residues and residuals of the plain pole-residue model, refitted on the same lines.

    :func:`lsfd` fits the modal terms as ``(jω/λ)^p R/(jω − λ)`` (the form whose residuals absorb
    the out-of-band modes best); a model file (``kind = "modal"``, see
    :class:`vibroscope.models.modal_model.PoleResidueModel`) stores the plain form
    ``R/(jω − λ) + conj(R)/(jω − conj λ) + LR (jω)^(p−2) + UR (jω)^p``. This refits `R`, `LR`
    and `UR` of that form by linear least squares on the measured FRF, for the poles of
    `result`, over its band.

    Parameters
    ----------
    frf : FRF
        The measured FRFs `result` was fitted to.
    result : LSFDResult
        Poles (and band, kind) to use.

    Returns
    -------
    residues : ndarray, complex, shape (n_modes, n_outputs, n_inputs)
        Residues of `H` at the poles (units of `H` × rad/s).
    lower, upper : ndarray, complex, shape (n_outputs, n_inputs)
        Coefficients of ``(jω)^(p−2)`` and ``(jω)^p``.
    """
    sel, _, _ = fit_band(frf, result.fmin, result.fmax)
    w = 2 * np.pi * frf.frequencies[sel]
    H = np.asarray(frf.H)[sel]
    nf, no, ni = H.shape
    poles = result.poles
    n = len(poles)
    p = result.power
    jw = 1j * w[:, None]
    a = 1 / (jw - poles[None, :])
    b = 1 / (jw - np.conj(poles)[None, :])
    lo, up = jw ** (p - 2), jw**p
    Phi = np.concatenate([a + b, 1j * (a - b), lo, 1j * lo, up, 1j * up], axis=1)
    A = np.concatenate([Phi.real, Phi.imag], axis=0)
    norm = np.linalg.norm(A, axis=0)
    norm[norm == 0] = 1.0
    B = np.concatenate([H.real, H.imag], axis=0).reshape(2 * nf, no * ni)
    x = np.linalg.lstsq(A / norm, B, rcond=None)[0] / norm[:, None]
    x = x.reshape(-1, no, ni)
    return x[:n] + 1j * x[n:2 * n], x[2 * n] + 1j * x[2 * n + 1], x[2 * n + 2] + 1j * x[2 * n + 3]
