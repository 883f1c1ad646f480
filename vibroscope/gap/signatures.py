"""Signature tests on the residual of the refitted linear model.

Each test returns a :class:`~vibroscope.gap.report.SignatureTest` with its statistic, the
threshold, the effects it points to, and an evidence curve for the figures.

References
----------
.. [1] L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, sec. 16.6
   (residual analysis: whiteness and cross-correlation with past inputs).
.. [2] K. Worden, G. R. Tomlinson, *Nonlinearity in Structural Dynamics*, IOP, 2001
   (level dependence of FRFs, coherence drop, restoring-force surface).
.. [3] R. Pintelon, J. Schoukens, *System Identification: A Frequency Domain Approach*,
   2nd ed., 2012 (BLA level dependence).
"""

from __future__ import annotations

import numpy as np

from vibroscope.gap.effects import EFFECT_TABLE
from vibroscope.gap.report import SignatureTest

__all__ = ["run_signatures"]

#: the effects that make the BLA depend on the excitation level (read from the one table)
_NONLIN = tuple(n for n, d in EFFECT_TABLE.items() if d.level_dependent)


def _by_trend(trend: str) -> tuple[str, ...]:
    """The level-dependent effects that can move a resonance the way `trend` says."""
    if trend not in ("hardening", "softening"):
        return _NONLIN
    return tuple(n for n in _NONLIN if EFFECT_TABLE[n].trend in (trend, "either") or EFFECT_TABLE[n].trend == "none")


def _binned(x, y, nb=25):
    """Mean of y in `nb` quantile bins of x (evidence curves)."""
    q = np.quantile(x, np.linspace(0.01, 0.99, nb + 1))
    q = np.unique(q)
    idx = np.clip(np.searchsorted(q, x) - 1, 0, len(q) - 2)
    xs = np.array([x[idx == i].mean() if np.any(idx == i) else np.nan for i in range(len(q) - 1)])
    ys = np.array([y[idx == i].mean() if np.any(idx == i) else np.nan for i in range(len(q) - 1)])
    ok = np.isfinite(xs) & np.isfinite(ys)
    return xs[ok], ys[ok]


def _corr(a, b) -> float:
    a = a - a.mean()
    b = b - b.mean()
    d = np.sqrt(np.sum(a * a) * np.sum(b * b))
    return float(np.sum(a * b) / d) if d > 0 else 0.0


def run_signatures(*, frequencies, H_levels, level_rms, H_meas, H_refit, coh, noise_coh, resid, u, states, fs,
                   out_channels, level_stat=None, input_unit: str = "N",
                   u_unit: str = "N") -> tuple[SignatureTest, ...]:
    """The signature tests.

    Parameters
    ----------
    frequencies : ndarray, shape (n_f,)
        Hz (excited band only).
    H_levels : list of ndarray of complex, shape (n_f, n_outputs)
        H1 per input level (lowest first); may be a single entry.
    level_rms : sequence of float
    H_meas, H_refit : ndarray of complex, shape (n_f, n_outputs)
        Measured H1 (all fitting data) and the refitted linear model's FRF.
    coh : ndarray, shape (n_f, n_outputs)
        Ordinary coherence.
    noise_coh : ndarray, shape (n_f, n_outputs)
        Coherence expected from the noise floor alone.
    resid : ndarray, shape (n_outputs, n)
        Measured minus refitted-model outputs on the fitting samples.
    u : ndarray, shape (n,)
    states : dict
        ``displacement``, ``velocity``: ndarray, shape (n_dofs, n) of the refitted model,
        ``relative``: dict pair -> (d, v).
    fs : float
    out_channels : list of str
    level_stat : dict, optional
        The BLA level test of the diagnosis (``stat``: the fraction of lines whose change
        between the lowest and highest level exceeds 3 standard deviations, ``flagged``, ``trend``,
        ``shift``); when given, it is the level-dependence test's statistic.
    input_unit : str, optional
        Unit of `level_rms`, the logged input's (a closed loop's reference: m); default 'N'.
    u_unit : str, optional
        Unit of `u` (a closed loop's actuator force: N); default 'N'.
    """
    f = frequencies
    tests = []
    # 1. level dependence of the BLA
    if len(H_levels) >= 2 and level_stat is not None and np.isfinite(level_stat.get("stat", np.nan)):
        lo, hi = H_levels[0], H_levels[-1]
        ratio_db = 20 * np.log10(np.maximum(np.abs(hi), 1e-300) / np.maximum(np.abs(lo), 1e-300))
        val = float(level_stat["stat"])
        trend = level_stat.get("trend", "none")
        tests.append(SignatureTest(
            name="level_dependence", value=val, threshold=0.01, flagged=bool(level_stat.get("flagged")),
            points_to=_by_trend(trend),
            detail=f"BLA change from the lowest to the highest level (input RMS {level_rms[0]:.3g} -> {level_rms[-1]:.3g} {input_unit}): "
                   f"{100 * val:.1f} % of the lines beyond 3 standard deviations; resonance {trend} "
                   f"({100 * level_stat.get('shift', 0.0):+.2f} %)",
            x=f, y=np.mean(ratio_db, axis=1), x_label="frequency [Hz]", y_label="H1 high / low level [dB]"))
    elif len(H_levels) >= 2:
        lo, hi = H_levels[0], H_levels[-1]
        w = np.clip(np.mean(coh, axis=1), 0, 1)
        ratio_db = 20 * np.log10(np.maximum(np.abs(hi), 1e-300) / np.maximum(np.abs(lo), 1e-300))
        rd = np.sum(w[:, None] * np.abs(ratio_db), axis=0) / max(np.sum(w), 1e-12)
        j = int(np.argmax(rd))  # the output of the largest change: the statistic's and the plot's
        val = float(rd[j])
        many = ratio_db.shape[1] > 1
        tests.append(SignatureTest(
            name="level_dependence", value=val, threshold=0.5, flagged=val > 0.5, points_to=_NONLIN,
            detail=f"mean |H(level {len(H_levels)}) / H(level 1)| = {val:.2f} dB "
                   + (f"at {out_channels[j]} (the largest of {ratio_db.shape[1]} outputs) " if many else "")
                   + f"(input RMS {level_rms[0]:.3g} -> {level_rms[-1]:.3g} {input_unit})",
            x=f, y=ratio_db[:, j], x_label="frequency [Hz]",
            y_label=f"H1 high / low level [dB]{f', {out_channels[j]}' if many else ''}"))
    # 2. coherence drop beyond the noise
    drop = float(np.mean(np.clip(noise_coh - coh, 0, 1)))
    tests.append(SignatureTest(
        name="coherence_drop", value=drop, threshold=0.02, flagged=drop > 0.02, points_to=_NONLIN,
        detail=f"mean coherence deficit against the noise-only expectation: {drop:.3f}",
        x=f, y=np.mean(coh, axis=1), x_label="frequency [Hz]", y_label="coherence"))
    # 3. phase slope of measured / refitted
    ratio = H_meas / np.where(np.abs(H_refit) > 0, H_refit, 1)
    wgt = np.mean(coh, axis=1)
    ph = np.unwrap(np.angle(np.sum(ratio * coh, axis=1)))
    if f.size > 3 and np.sum(wgt) > 0:
        A = np.vstack([f, np.ones_like(f)]).T * np.sqrt(wgt)[:, None]
        sl, _ = np.linalg.lstsq(A, ph * np.sqrt(wgt), rcond=None)[0]
        tau = float(-sl / (2 * np.pi))
    else:
        tau = 0.0
    tests.append(SignatureTest(
        name="phase_slope", value=tau, threshold=2e-4, flagged=tau > 2e-4, points_to=("time_delay",),
        detail=f"phase of measured / refitted FRF falls like a delay of {1e3 * tau:.2f} ms",
        x=f, y=np.degrees(ph), x_label="frequency [Hz]", y_label="phase(measured / refit) [deg]"))
    # 4. extra poles: peaks of |measured / refitted|
    mag = 20 * np.log10(np.maximum(np.mean(np.abs(ratio), axis=1), 1e-300))
    pk = float(np.max(np.abs(mag - np.median(mag)))) if mag.size else 0.0
    tests.append(SignatureTest(
        name="extra_poles", value=pk, threshold=3.0, flagged=pk > 3.0, points_to=("extra_mode",),
        detail=f"largest local deviation of |measured / refitted FRF|: {pk:.1f} dB",
        x=f, y=mag, x_label="frequency [Hz]", y_label="|measured / refit| [dB]"))
    # 5-7. residual versus state
    r = resid[0] if resid.ndim == 2 else resid
    rel = states.get("relative", {})
    if rel:
        best = max(rel.items(), key=lambda kv: abs(_corr(r, np.tanh(kv[1][1] / (0.05 * np.std(kv[1][1]) + 1e-300)))))
        pair, (d, v) = best
        c = _corr(r, np.tanh(v / (0.05 * np.std(v) + 1e-300)))
        xs, ys = _binned(v, r)
        tests.append(SignatureTest(
            name="residual_vs_velocity", value=abs(c), threshold=0.1, flagged=abs(c) > 0.1,
            points_to=("coulomb_friction", "hysteresis"),
            detail=f"residual correlates with sign(v) across {pair}: r = {c:+.2f}", x=xs, y=ys,
            x_label=f"relative velocity {pair} [m/s]", y_label=f"residual {out_channels[0]}"))
        best = max(rel.items(), key=lambda kv: abs(_corr(r, kv[1][0] ** 3)))
        pair, (d, v) = best
        c3 = _corr(r, d**3)
        xs, ys = _binned(d, r)
        tests.append(SignatureTest(
            name="residual_vs_displacement", value=abs(c3), threshold=0.1, flagged=abs(c3) > 0.1,
            points_to=("cubic_stiffness", "backlash"),
            detail=f"residual correlates with d^3 across {pair}: r = {c3:+.2f}", x=xs, y=ys,
            x_label=f"relative displacement {pair} [m]", y_label=f"residual {out_channels[0]}"))
    ua = u - u.mean()
    q = np.quantile(np.abs(ua), 0.9)
    exc = np.sign(ua) * np.maximum(np.abs(ua) - q, 0)
    ci = _corr(r, exc)
    xs, ys = _binned(ua, r)
    tests.append(SignatureTest(
        name="residual_vs_input", value=abs(ci), threshold=0.1, flagged=abs(ci) > 0.1, points_to=("saturation",),
        detail=f"residual correlates with the input beyond its 90 % quantile: r = {ci:+.2f}",
        x=xs, y=ys, x_label=f"input [{u_unit}]", y_label=f"residual {out_channels[0]}"))
    # 8. whiteness (Ljung): fraction of autocorrelation lags 1..50 outside +-2.58/sqrt(N)
    n = r.size
    rr = r - r.mean()
    lags = np.arange(1, 51)
    den = float(np.sum(rr * rr)) or 1.0
    ac = np.array([np.sum(rr[:-k] * rr[k:]) / den for k in lags])
    frac = float(np.mean(np.abs(ac) > 2.58 / np.sqrt(n)))
    tests.append(SignatureTest(
        name="residual_whiteness", value=frac, threshold=0.2, flagged=frac > 0.2, points_to=(),
        detail=f"{100 * frac:.0f} % of residual autocorrelation lags 1-50 outside the 99 % band",
        x=lags / fs, y=ac, x_label="lag [s]", y_label="residual autocorrelation"))
    # 9. cross-correlation residual / past input (Ljung)
    uu = ua / (np.std(ua) or 1.0)
    rn = rr / (np.std(rr) or 1.0)
    lags2 = np.arange(0, 51)
    cc = np.array([np.mean(rn[k:] * uu[: n - k]) for k in lags2])
    fr2 = float(np.mean(np.abs(cc) > 2.58 / np.sqrt(n)))
    tests.append(SignatureTest(
        name="input_cross_correlation", value=fr2, threshold=0.2, flagged=fr2 > 0.2,
        points_to=("time_delay", "extra_mode", "parameter_mismatch"),
        detail=f"{100 * fr2:.0f} % of residual / past-input cross-correlation lags 0-50 outside the 99 % band",
        x=lags2 / fs, y=cc, x_label="lag [s]", y_label="cross-correlation residual / input"))
    return tuple(tests)
