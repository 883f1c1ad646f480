"""Result objects of the sim-to-real gap diagnosis (:func:`vibroscope.gap.diagnose`).

All are small frozen dataclasses; arrays are read-only. :class:`GapReport` carries the
fixed report keys (:meth:`GapReport.to_dict`) and the traces and spectra its figures need
(:meth:`GapReport.plot`, :func:`vibroscope.viewers.gap_figures.plot_gap_report`).

Metric
------
``nrmse = sqrt(mean_c (sum_k (y_ck - yhat_ck)^2 / sum_k y_ck^2))``: each output channel's
squared error normalised by its own energy, averaged over the channels (channels of different
units count alike; one channel: ``RMS(y - yhat) / RMS(y)``), evaluated on held-out
(validation) samples only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from vibroscope._checks import read_only as _ro
from vibroscope.gap.effects import EFFECT_TABLE

__all__ = [
    "EFFECTS",
    "Band",
    "ChannelGap",
    "RegimeGap",
    "Candidate",
    "SignatureTest",
    "GapTraces",
    "GapSpectrum",
    "GapReport",
]

#: the effect vocabulary, read from its one table (:data:`vibroscope.gap.effects.EFFECT_TABLE`)
EFFECTS = tuple(EFFECT_TABLE)
#: the summary says what the period-to-period variation of a periodic input's outputs measures
#: when it exceeds the white noise floor by more than this factor
PERIOD_FLOOR_NOTE = 2.0


def _num(x):
    """JSON-friendly float (None for NaN/inf)."""
    if x is None:
        return None
    x = float(x)
    return x if np.isfinite(x) else None


def _levels_dict(ev) -> dict | None:
    """The level evidence as JSON: per level its input RMS, per mode f_n and zeta (with std)."""
    if ev is None:
        return None
    return {
        "level_dependent": bool(ev.level_dependent),
        "trend": ev.trend,
        "damping_rises": bool(ev.damping_rises),
        "description": ev.description,
        "levels": [{"log": int(lv.log), "level": int(lv.level), "input_rms": _num(lv.rms),
                    "natural_frequencies_hz": [_num(x) for x in lv.natural_frequencies],
                    "natural_frequency_std_hz": [_num(x) for x in lv.natural_frequency_std],
                    "damping_ratios": [_num(x) for x in lv.damping_ratios],
                    "damping_std": [_num(x) for x in lv.damping_std]} for lv in ev.levels],
    }


@dataclass(frozen=True)
class Band:
    """A frequency band holding a share of the gap energy.

    Attributes
    ----------
    fmin, fmax : float
        Band edges in Hz (JSON keys ``f_lo_hz``, ``f_hi_hz``).
    share : float
        Fraction (0..1) of the residual (measured - nominal) energy in the band.
    """

    fmin: float
    fmax: float
    share: float

    def to_dict(self) -> dict:
        """The band as a JSON-ready dict: ``f_lo_hz``, ``f_hi_hz``, ``share``; NaN and inf become None."""
        return {"f_lo_hz": _num(self.fmin), "f_hi_hz": _num(self.fmax), "share": _num(self.share)}


@dataclass(frozen=True, kw_only=True)
class ChannelGap:
    """Gap of one output channel on the held-out samples: nrmse of the nominal model
    (`gap`) and of the verdict's model (`gap_after`), and the RMS simulation errors in the
    channel's unit (`rms_error`, `rms_error_after`).

    Attributes
    ----------
    channel : str
        The output channel (message path).
    gap : float
        nrmse of the nominal model on the held-out samples.
    gap_after : float
        nrmse of the verdict's model there; NaN (default) when not evaluated.
    rms_error : float
        RMS of measured - nominal simulation, in `unit`; default NaN.
    rms_error_after : float
        RMS of measured - verdict model's simulation, in `unit`; default NaN.
    unit : str
        The channel's unit (e.g. ``"m/s^2"``); default ``""``.
    """

    channel: str
    gap: float
    gap_after: float = float("nan")
    rms_error: float = float("nan")
    rms_error_after: float = float("nan")
    unit: str = ""

    def to_dict(self) -> dict:
        """The channel's gap as a JSON-ready dict: every field by its name; NaN and inf become None."""
        return {"channel": self.channel, "gap": _num(self.gap), "gap_after": _num(self.gap_after),
                "rms_error": _num(self.rms_error), "rms_error_after": _num(self.rms_error_after), "unit": self.unit}


@dataclass(frozen=True)
class RegimeGap:
    """Gap restricted to a state regime or an excitation level.

    Attributes
    ----------
    kind : {"regime", "level"}
    name : str
        ``near_zero_velocity``, ``large_displacement``, ``input_peaks``, ``rest`` or
        ``level_1`` (lowest input RMS) ... ``level_n``.
    gap : float
        nrmse of the nominal model on those samples.
    fraction : float
        Fraction of the samples in the regime.
    """

    kind: str
    name: str
    gap: float
    fraction: float

    def to_dict(self) -> dict:
        """The regime's gap as a JSON-ready dict: every field by its name; NaN and inf become None."""
        return {"kind": self.kind, "name": self.name, "gap": _num(self.gap), "fraction": _num(self.fraction)}


@dataclass(frozen=True, kw_only=True)
class Candidate:
    """One candidate effect, fitted and scored on held-out data.

    Attributes
    ----------
    effect : str
        One of :data:`EFFECTS`.
    where : dict
        ``{"between": [a, b]}``, ``{"dof": name, "frequency_hz": f}``, ``{"side": "input"}``
        or ``{"parameters": [...]}``; qualifiers such as ``"character"`` (hardening, softening),
        ``"form"`` (jenkins, iwan) and ``"linear_base"`` (``"nominal"`` or ``"refit"``: a second
        fit of the effect at this location, kept on the other linear base because the better
        fit made the effect vanish).
    parameters : dict
        Fitted effect parameters in SI units (``delay_s``, ``limit_N``, ``Fc_N``, ``gap_m``,
        ``k3_N_per_m3``, ``alpha_N_per_m`` ...).
    gap_after : float
        Held-out nrmse of the model augmented with this effect (linear parameters refitted).
    score : float
        Ranking score: the held-out share of the nominal model's excess gap (above the
        noise floor) that the candidate explains, minus a complexity penalty.
    gap_fit : float
        nrmse on the fitting data.
    n_parameters : int
        Number of effect parameters fitted (besides the linear ones).
    model_toml : str
        The augmented model as a model file.
    vanished : str
        Why the fitted parameters make the effect vanish (a delay below half a sample, a
        clearance far below the rms deflection, an effect that changes the held-out outputs
        by less than the noise floor ...); such a candidate is never the verdict. Empty when
        it does not vanish.
    """

    effect: str
    where: Mapping[str, Any]
    parameters: Mapping[str, float]
    gap_after: float
    score: float
    gap_fit: float = float("nan")
    n_parameters: int = 0
    model_toml: str = ""
    vanished: str = ""

    def to_dict(self) -> dict:
        """The candidate as a JSON-ready dict: ``effect``, ``where``, ``parameters``, ``gap_after``, ``score``,
        ``gap_fit``, ``n_parameters``, ``vanished`` (the reason, or None) and ``model_toml`` (the fitted
        model as a model file); NaN and inf become None."""
        return {
            "effect": self.effect,
            "where": dict(self.where),
            "parameters": {k: _num(v) for k, v in self.parameters.items()},
            "gap_after": _num(self.gap_after),
            "score": _num(self.score),
            "gap_fit": _num(self.gap_fit),
            "n_parameters": int(self.n_parameters),
            "vanished": self.vanished or None,
            "model_toml": self.model_toml,
        }


@dataclass(frozen=True, kw_only=True)
class SignatureTest:
    """One signature test on the residual of the refitted linear model.

    Attributes
    ----------
    name : str
        ``level_dependence``, ``coherence_drop``, ``phase_slope``, ``residual_vs_velocity``,
        ``residual_vs_displacement``, ``residual_vs_input``, ``extra_poles``,
        ``residual_whiteness``, ``input_cross_correlation`` ...
    value : float
        The test statistic.
    threshold : float
        The value beyond which the test flags.
    flagged : bool
    points_to : tuple of str
        Effects the test points to when flagged.
    detail : str
        One line for people.
    x, y : ndarray, optional
        Evidence curve for the figure (e.g. binned velocity vs mean residual).
    x_label, y_label : str
    """

    name: str
    value: float
    threshold: float
    flagged: bool
    points_to: tuple[str, ...] = ()
    detail: str = ""
    x: np.ndarray | None = None
    y: np.ndarray | None = None
    x_label: str = ""
    y_label: str = ""

    def to_dict(self) -> dict:
        """The test as a JSON-ready dict: ``name``, ``value``, ``threshold``, ``flagged``, ``points_to``,
        ``detail`` (not the evidence curve); NaN and inf become None."""
        return {
            "name": self.name,
            "value": _num(self.value),
            "threshold": _num(self.threshold),
            "flagged": bool(self.flagged),
            "points_to": list(self.points_to),
            "detail": self.detail,
        }


@dataclass(frozen=True, kw_only=True)
class GapTraces:
    """Time traces for the figures: measured, nominal, refitted and augmented outputs.

    Attributes
    ----------
    fs : float
        Sampling frequency in Hz.
    t0 : float
        Time of the first sample in s.
    channels : tuple of str
        Output channels (rows).
    units : tuple of str
    measured, nominal, refit, augmented : ndarray, shape (n_outputs, n_samples)
        In the channels' units.
    validation : ndarray of bool, shape (n_samples,)
        True on held-out samples.
    input : ndarray, shape (n_samples,)
        The (first) input channel, N.
    log : str
        Which log (file name) the traces come from.
    """

    fs: float
    t0: float
    channels: tuple[str, ...]
    units: tuple[str, ...]
    measured: np.ndarray
    nominal: np.ndarray
    refit: np.ndarray
    augmented: np.ndarray
    validation: np.ndarray
    input: np.ndarray
    log: str = ""

    def __post_init__(self) -> None:
        for name in ("measured", "nominal", "refit", "augmented", "validation", "input"):
            object.__setattr__(self, name, _ro(getattr(self, name)))

    @property
    def time(self) -> np.ndarray:
        """Sample times in s from the first sample, shape (n_samples,)."""
        return np.arange(self.measured.shape[1]) / self.fs


@dataclass(frozen=True, kw_only=True)
class GapSpectrum:
    """Spectra of the gap (Welch, ``scaling='density'``), per output channel.

    Attributes
    ----------
    frequencies : ndarray, shape (n_f,)
        Hz.
    measured : ndarray, shape (n_outputs, n_f)
        PSD of the measured outputs (unit^2/Hz).
    residual_before, residual_refit, residual_after : ndarray, shape (n_outputs, n_f)
        PSD of measured - nominal / refitted / augmented.
    noise : ndarray, shape (n_outputs, n_f)
        Estimated noise-floor PSD.
    frf_frequencies : ndarray, shape (n_ff,)
    frf_measured, frf_nominal, frf_augmented : ndarray of complex, shape (n_ff, n_outputs)
        H1 estimate from the log and the models' simulated H1 (first input); NaN at the lines
        that carry no input (more than 30 dB below the input's strongest line).
    coherence : ndarray, shape (n_ff, n_outputs)
    residual_before_coherent : ndarray, shape (n_outputs, n_f), optional
        The part of ``residual_before`` coherent with the logged input(s), ``G_ru G_uu^-1 G_ur``
        (NaN where the input carries nothing): what a linear model of the input could still
        remove; the rest is noise, an unlogged disturbance or a nonlinearity's distortion.
        None when not computed.
    """

    frequencies: np.ndarray
    measured: np.ndarray
    residual_before: np.ndarray
    residual_refit: np.ndarray
    residual_after: np.ndarray
    noise: np.ndarray
    frf_frequencies: np.ndarray
    frf_measured: np.ndarray
    frf_nominal: np.ndarray
    frf_augmented: np.ndarray
    coherence: np.ndarray
    residual_before_coherent: np.ndarray | None = None

    def __post_init__(self) -> None:
        for f in self.__dataclass_fields__:
            if getattr(self, f) is not None:
                object.__setattr__(self, f, _ro(getattr(self, f)))


@dataclass(frozen=True, kw_only=True)
class GapReport:
    """The sim-to-real gap diagnosis of a model against one or more logs.

    Attributes
    ----------
    metric : str
        ``"nrmse"``.
    validation : str
        Which data the gaps are measured on (never used for fitting).
    noise_floor : float
        nrmse that measurement noise alone gives, estimated from the data.
    noise_floor_method : str
        How it was estimated.
    gap_before, gap_refit, gap_after : float
        Held-out nrmse of the nominal model, of the nominal structure with re-estimated
        linear parameters, and of the model augmented with the verdict's effect.
    shrink : float
        ``1 - gap_after / gap_before``.
    bands : tuple of Band
    channels : tuple of ChannelGap
    regimes : tuple of RegimeGap
    candidates : tuple of Candidate
        Every effect tried, best first.
    signatures : tuple of SignatureTest
    verdict : str
        The winning effect (the first, when several are named); ``"none"`` when the nominal
        model is within the noise floor; ``"unexplained"`` when the gap is above the floor
        and no admissible candidate explains enough of it on held-out data.
    verdicts : tuple of str
        Every effect named, in the order forward selection added them (one for a single
        effect, ``("none",)`` or ``("unexplained",)`` otherwise).
    shares : tuple of float
        Each named effect's share of the shrink of the held-out gap (sums to 1); empty
        without an effect.
    model_name : str
    augmented_model_toml : str
        The augmented (verdict) model as a model file (``--export-model``).
    traces : GapTraces or None
    spectrum : GapSpectrum or None
    timings : dict
        Seconds per stage (``held_clearance``, where made, is part of ``forward_selection``).
    meta : dict
        Settings and provenance.
    level_evidence : LevelEvidence or None
        The BLA per log and excitation level with each resonance's natural frequency and
        damping ratio per level (:func:`vibroscope.gap.levels.level_blas`); None when it could
        not be estimated.
    """

    metric: str
    validation: str
    noise_floor: float
    noise_floor_method: str
    gap_before: float
    gap_refit: float
    gap_after: float
    shrink: float
    bands: tuple[Band, ...]
    channels: tuple[ChannelGap, ...]
    regimes: tuple[RegimeGap, ...]
    candidates: tuple[Candidate, ...]
    signatures: tuple[SignatureTest, ...]
    verdict: str
    verdicts: tuple[str, ...] = ()
    shares: tuple[float, ...] = ()
    model_name: str = ""
    augmented_model_toml: str = ""
    traces: GapTraces | None = None
    spectrum: GapSpectrum | None = None
    timings: Mapping[str, float] = field(default_factory=dict)
    meta: Mapping[str, Any] = field(default_factory=dict)
    level_evidence: Any = None

    @property
    def best(self) -> Candidate | None:
        """The top-ranked candidate (None when no candidate was tried)."""
        return self.candidates[0] if self.candidates else None

    def to_dict(self) -> dict:
        """The report as JSON-ready dict (fixed keys first; arrays left out)."""
        return {
            "metric": self.metric,
            "validation": self.validation,
            "noise_floor": _num(self.noise_floor),
            "noise_floor_method": self.noise_floor_method,
            "gap_before": _num(self.gap_before),
            "gap_refit": _num(self.gap_refit),
            "gap_after": _num(self.gap_after),
            "shrink": _num(self.shrink),
            "bands": [b.to_dict() for b in self.bands],
            "channels": [c.to_dict() for c in self.channels],
            "regimes": [r.to_dict() for r in self.regimes],
            "candidates": [c.to_dict() for c in self.candidates],
            "signatures": [s.to_dict() for s in self.signatures],
            "verdict": list(self.verdicts) if len(self.verdicts) > 1 else self.verdict,
            "shares": [_num(x) for x in self.shares],
            "model": self.model_name,
            "timings_s": {k: _num(v) for k, v in self.timings.items()},
            "meta": dict(self.meta),
            "levels": _levels_dict(self.level_evidence),
        }

    def summary(self) -> str:
        """A few lines for people: verdict, gaps, bands, the top candidates."""
        named = self.verdicts if len(self.verdicts) > 1 else (self.verdict,)
        share = (" (" + ", ".join(f"{e} {100 * x:.0f} %" for e, x in zip(named, self.shares)) + " of the shrink)"
                 if len(named) > 1 and self.shares else "")
        lines = [
            f"verdict: {' + '.join(named)}{share}",
            f"gap (nrmse, {self.validation}): nominal {self.gap_before:.4f}, refit {self.gap_refit:.4f}, "
            f"augmented {self.gap_after:.4f} (shrink {100 * self.shrink:.1f} %), noise floor {self.noise_floor:.4f}",
        ]
        rank = (self.meta or {}).get("noise_floor_ranking") or {}
        if isinstance(rank.get("nrmse"), float) and rank["nrmse"] < 0.99 * self.noise_floor:
            lines.append(f"candidates ranked against a floor of {rank['nrmse']:.4f}: {rank.get('method', '')}")
        for label, pr in ((self.meta or {}).get("predictability") or {}).get("models", {}).items():
            if pr.get("unpredictable"):
                d = pr.get("self_disagreement")
                by = f"differ by nrmse {d:.4f}" if d is not None else "are not both finite"
                lines.append(f"{label} is not predictable: its own outputs at twice the integration sub-steps {by} "
                             f"(noise floor {pr['noise_floor']:.4f}); the gap it leaves is not searched for further "
                             "effects")
        pfl = ((self.meta or {}).get("incoherent_gap") or {}).get("period_floor")
        if pfl and pfl.get("ratio_to_white_floor") and pfl["ratio_to_white_floor"] > PERIOD_FLOOR_NOTE:
            why = (f"growing with the input level (relative {min(pfl['run_nrmse']):.4f} to "
                   f"{max(pfl['run_nrmse']):.4f}): the response itself stops repeating (chaos or a subharmonic), "
                   "not a noise floor" if pfl.get("grows_with_level") else
                   f"{pfl['ratio_to_white_floor']:.3g} x the white noise floor: noise in the band or an unlogged "
                   "disturbance (or a response that does not repeat) that no model of the logged input can explain")
            lines.append(f"the outputs vary from period to period by nrmse {pfl['nrmse']:.4f} over "
                         f"{pfl['n_periods']} periods, {why}")
        inc = (self.meta or {}).get("incoherent_gap") or {}
        if inc.get("changed"):
            lines.append(f"not coherent with the input: {inc['changed']}")
        elif inc.get("repeats"):
            lines.append(f"not coherent with the input, {inc['repeats']}")
        if self.bands:
            lines.append("bands: " + ", ".join(f"{b.fmin:.1f}-{b.fmax:.1f} Hz ({100 * b.share:.0f} %)" for b in self.bands))
        n_named = len(named) if len(named) > 1 else 1
        for i, c in enumerate(self.candidates[:max(5, n_named + 2)], 1):
            where = ", ".join(f"{k}={v}" for k, v in c.where.items())
            par = ", ".join(f"{k}={v:.4g}" for k, v in c.parameters.items())
            van = f"  (vanishes: {c.vanished})" if c.vanished else ""
            name = f"+ {c.effect}" if 1 < i <= n_named else c.effect  # added by forward selection: the combined gap
            lines.append(f"  {i}. {name:<18} gap {c.gap_after:.4f}  score {c.score:+.3f}  [{where}] {par}{van}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"GapReport(verdict={self.verdict!r}, gap_before={self.gap_before:.4g}, gap_after={self.gap_after:.4g})"

    def plot(self, out_dir=None):
        """Figures of the diagnosis (lazy matplotlib, :mod:`vibroscope.viewers.gap_figures`).

        Parameters
        ----------
        out_dir : str or Path, optional
            Also write each figure as ``NAME.png`` there (created if missing); default None.

        Returns
        -------
        dict
            Name -> matplotlib Figure (see
            :func:`~vibroscope.viewers.gap_figures.plot_gap_report`).
        """
        from vibroscope._plotting import draw

        return draw("plot_gap_report", self, out_dir=out_dir)
