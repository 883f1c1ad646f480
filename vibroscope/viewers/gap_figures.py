"""Matplotlib figures of a sim-to-real gap diagnosis (:class:`vibroscope.gap.report.GapReport`).

:func:`plot_gap_report` draws them all (and writes ``NAME.png`` with `out_dir`):

``gap_time``
    Per output channel: measured vs nominal vs augmented over the record (held-out spans
    shaded), and a zoom around the largest held-out |measured - nominal|.
``gap_frf``
    |H| (dB) and phase of the measured H1, the nominal and the augmented model per output,
    coherence underneath.
``gap_spectrum``
    PSD of the measured outputs and of the residuals of the nominal, refitted and augmented
    models, with the noise floor; the located bands shaded and labelled with their share.
``gap_evidence``
    One panel per signature test with an evidence curve; flagged tests highlighted.
``gap_candidates``
    Held-out gap of every candidate, with the nominal gap, the refit gap and the noise floor;
    the verdict highlighted.

matplotlib is imported inside the functions (Agg when there is no display), so importing this
module costs nothing.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from vibroscope.viewers.figures import pyplot, save_figure, short_label

__all__ = ["plot_gap_report", "plot_gap_time", "plot_gap_frf", "plot_gap_spectrum", "plot_gap_evidence",
           "plot_gap_candidates", "where_label", "candidate_label", "verdict_index", "zoom_window",
           "held_out_spans", "FIGURES", "plot_level_evidence"]

#: names of the figures, in the order :func:`plot_gap_report` draws them
FIGURES = ("gap_time", "gap_frf", "gap_spectrum", "gap_evidence", "gap_candidates", "gap_levels")

#: line colours of the traces (the same in every figure)
COLORS = {"measured": "k", "nominal": "C3", "refit": "C1", "augmented": "C2", "noise": "0.45"}
#: colours of the candidate bars
BAR = "#9bb4cc"
BAR_VERDICT = "C2"
#: shade of the held-out spans and of the bands
HELD_OUT = "#fff1c9"
BAND = "C4"


# --------------------------------------------------------------------------------------------
# small helpers (shared with :mod:`vibroscope.viewers.rerun_gap`)
# --------------------------------------------------------------------------------------------

def where_label(where: Mapping[str, Any]) -> str:
    """Short text of a candidate's ``where``.

    ``{"between": ["m1", "ground"]}`` -> ``"m1–ground"``; ``{"dof": "m2", "frequency_hz": 12.3}``
    -> ``"m2, 12.3 Hz"``; ``{"side": "input"}`` -> ``"input"``; ``{"parameters": ["k1", "c1"]}``
    -> ``"k1, c1"``; ``{}`` -> ``""``.

    Parameters
    ----------
    where : mapping of str to object
        A candidate's location (:attr:`vibroscope.gap.report.Candidate.where`); other keys
        are written ``key=value``; more than four parameters are shortened to ``+n``.

    Returns
    -------
    str
    """
    if not where:
        return ""
    bits = []
    for k, v in where.items():
        if k == "between" and isinstance(v, (list, tuple)):
            bits.append("–".join(str(x) for x in v))
        elif k == "frequency_hz":
            if v is not None and np.isfinite(float(v)):
                bits.append(f"{float(v):.3g} Hz")
        elif k == "parameters" and isinstance(v, (list, tuple)):
            names = [str(x) for x in v]
            bits.append(", ".join(names[:4]) + (f" +{len(names) - 4}" if len(names) > 4 else "") if names
                        else "no change")
        elif k in ("dof", "side", "character", "form"):
            bits.append(str(v))
        else:
            bits.append(f"{k}={v}")
    return ", ".join(bits)


def candidate_label(candidate) -> str:
    """``"effect @ where"`` (just ``"effect"`` when the candidate has no location); an
    effect fitted in several forms names its form beside it: ``"joint_friction (iwan) @ m1–ground"``.

    Parameters
    ----------
    candidate : Candidate
        Any object with ``effect`` and ``where`` attributes (:func:`where_label`).

    Returns
    -------
    str
    """
    where = dict(candidate.where)
    form = where.pop("form", None)
    name = f"{candidate.effect} ({form})" if form else str(candidate.effect)
    w = where_label(where)
    return f"{name} @ {w}" if w else name


def verdict_index(report) -> int | None:
    """Index in ``report.candidates`` of the verdict's candidate (the first of its effect), or None.

    Parameters
    ----------
    report : GapReport
        The diagnosis; its ``verdict`` is compared with each candidate's ``effect``.

    Returns
    -------
    int or None
        None when no candidate has the verdict's effect.
    """
    for k, c in enumerate(report.candidates):
        if c.effect == report.verdict:
            return k
    return None


def held_out_spans(validation: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in a boolean mask, as ``(start, stop)`` sample index pairs (stop exclusive).

    Parameters
    ----------
    validation : array_like of bool, shape (n_samples,)
        The held-out samples (raveled).

    Returns
    -------
    list of tuple of (int, int)
        In sample order; empty for an empty or all-False mask.
    """
    v = np.asarray(validation, dtype=bool).ravel()
    if v.size == 0:
        return []
    d = np.diff(np.concatenate([[0], v.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def zoom_window(traces, width_s: float = 0.75) -> tuple[int, int, int]:
    """Sample range around the largest held-out |measured - nominal|.

    The residual of each channel is normalised by the channel's RMS and summed in quadrature;
    its largest value on the held-out samples (every sample when none is held out) is the
    centre of a window `width_s` long (at least 20 samples, at most the record), kept inside
    the record.

    Parameters
    ----------
    traces : GapTraces
        Its ``measured`` and ``nominal`` outputs, ``validation`` mask and ``fs`` (Hz) are used.
    width_s : float, optional
        Window length in s; default 0.75.

    Returns
    -------
    start, stop : int
        Sample indices (stop exclusive).
    peak : int
        Sample of the largest residual.
    """
    m = np.atleast_2d(np.asarray(traces.measured, dtype=float))
    r = m - np.atleast_2d(np.asarray(traces.nominal, dtype=float))
    n = m.shape[1]
    if n == 0:
        return 0, 0, 0
    rms = np.sqrt(np.nanmean(m ** 2, axis=1))
    rms = np.where(np.isfinite(rms) & (rms > 0), rms, 1.0)
    e = np.nansum((r / rms[:, None]) ** 2, axis=0)
    val = np.asarray(traces.validation, dtype=bool).ravel()
    mask = val if val.shape == (n,) and val.any() else np.ones(n, bool)
    e = np.where(mask & np.isfinite(e), e, -np.inf)
    peak = int(np.argmax(e))
    w = int(min(n, max(20, round(width_s * traces.fs))))
    start = int(np.clip(peak - w // 2, 0, n - w))
    return start, start + w, peak


def _channel_names(report, n: int) -> list[str]:
    if report.traces is not None and len(report.traces.channels) == n:
        return [str(c) for c in report.traces.channels]
    if len(report.channels) == n:
        return [c.channel for c in report.channels]
    return [f"output {k + 1}" for k in range(n)]


def _units(report, n: int) -> list[str]:
    if report.traces is not None and len(report.traces.units) == n:
        return [str(u) for u in report.traces.units]
    return [""] * n


def _psd_unit(u: str) -> str:
    if not u:
        return "unit^2/Hz"
    return f"({u})^2/Hz" if any(ch in u for ch in "/*^ ") else f"{u}^2/Hz"


def _channel_gap(report, name: str):
    for c in report.channels:
        if c.channel == name:
            return c
    return None


def _input_unit(report) -> str:
    """Unit of the report's first input (N unless the report says otherwise)."""
    return str((getattr(report, "meta", None) or {}).get("input_unit") or "N")


def _fmt(x: float, spec: str = ".3f") -> str:
    if x is None or not np.isfinite(float(x)):
        return "n/a"
    if spec == ".3f" and 0 < abs(float(x)) < 5e-3:  # small gaps keep their digits (1.2e-05, not 0.000)
        return format(float(x), ".2g")
    return format(float(x), spec)


def _positive(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return np.where(v > 0, v, np.nan)


def _db(v: np.ndarray, fac: float = 20.0) -> np.ndarray:
    a = np.abs(np.asarray(v))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(a > 0, fac * np.log10(np.where(a > 0, a, 1.0)), np.nan)


def _new_figure(figsize, fig=None):
    if fig is None:
        plt = pyplot()
        return plt.figure(figsize=figsize, layout="constrained")
    fig.clf()
    return fig


# --------------------------------------------------------------------------------------------
# figures
# --------------------------------------------------------------------------------------------

def _minmax(t: np.ndarray, x: np.ndarray, nb: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-bin minimum and maximum of `x` over `nb` equal bins, with each bin's start time."""
    edges = np.linspace(0, x.size, nb + 1).astype(int)[:-1]
    with np.errstate(invalid="ignore"):
        return t[edges], np.fmin.reduceat(x, edges), np.fmax.reduceat(x, edges)


def plot_gap_time(report, *, fig=None, zoom_s: float = 0.75, max_points: int = 4000):
    """Measured vs nominal vs augmented outputs over the record, and a zoom on the worst gap.

    One row per output channel: the whole record on the left, held-out (validation) spans
    shaded; on the right `zoom_s` seconds around the largest held-out |measured - nominal|
    (:func:`zoom_window`, the same window for every channel, outlined on the left panels).
    Records longer than `max_points` samples are drawn on the left as per-bin min–max
    envelopes (at most 300 bins; measured filled grey over the models' envelope lines), which
    shows where a model over- or undershoots at the scale of the record; the zoom always
    shows the samples.

    Parameters
    ----------
    report : GapReport
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.
    zoom_s : float, optional
        Width of the zoom in s.
    max_points : int, optional
        Longer records are drawn as min–max envelopes on the left.

    Returns
    -------
    matplotlib.figure.Figure or None
        None when the report has no traces (or no samples).
    """
    tr = report.traces
    if tr is None or np.asarray(tr.measured).size == 0:
        return None
    meas = np.atleast_2d(np.asarray(tr.measured, dtype=float))
    n_ch, n = meas.shape
    t = np.arange(n) / tr.fs
    names = _channel_names(report, n_ch)
    units = _units(report, n_ch)
    series = [("measured", meas, 1.0), ("nominal", np.atleast_2d(tr.nominal), 0.9),
              ("augmented", np.atleast_2d(tr.augmented), 0.9)]
    aug_name = f"augmented ({_verdict_words(report)})"
    spans = held_out_spans(tr.validation)
    z0, z1, peak = zoom_window(tr, zoom_s)
    envelope = n > max_points
    n_bins = max(2, min(max_points // 2, 300))
    env = f"; min–max per {n / n_bins / tr.fs:.3g} s bin" if envelope else ""
    fig = _new_figure((12, 1.3 + 2.5 * n_ch), fig)
    axes = fig.subplots(n_ch, 2, squeeze=False, sharex="col", gridspec_kw={"width_ratios": [3, 1.25]})
    for c in range(n_ch):
        axf, axz = axes[c]
        for ax in (axf, axz):
            for k, (a, b) in enumerate(spans):
                ax.axvspan(t[a], t[b - 1] + 1 / tr.fs, color=HELD_OUT, lw=0, zorder=0,
                           label="held-out (validation)" if k == 0 else None)
        for what, y, lw in series:
            label = aug_name if what == "augmented" else what
            yc = np.asarray(y[c], dtype=float)
            if envelope:
                tb, lo, hi = _minmax(t, yc, n_bins)
                if what == "measured":  # on top, half transparent: a model shows where it leaves it
                    axf.fill_between(tb, lo, hi, color="0.25", lw=0, alpha=0.45, zorder=2.5, label=label)
                else:
                    axf.plot(tb, hi, color=COLORS[what], lw=0.8, label=label)
                    axf.plot(tb, lo, color=COLORS[what], lw=0.8)
            else:
                axf.plot(t, yc, color=COLORS[what], lw=0.7 * lw, alpha=0.9 if what != "measured" else 1.0, label=label)
            axz.plot(t[z0:z1], yc[z0:z1], color=COLORS[what], lw=1.2 * lw, alpha=0.9 if what != "measured" else 1.0,
                     label=label)
        for ax in (axf, axz):
            ax.grid(True, alpha=0.35)
        if z1 > z0:
            axf.axvspan(t[z0], t[z1 - 1], facecolor="none", edgecolor="0.3", ls="--", lw=0.9, zorder=3,
                        label="zoom")
        u = units[c] or "-"
        axf.set_ylabel(f"{short_label(names[c], 28)} [{u}]", fontsize=8)
        cg = _channel_gap(report, names[c])
        gap = f": held-out nrmse nominal {_fmt(cg.gap)} → augmented {_fmt(cg.gap_after)}" if cg else ""
        axf.set_title(f"{short_label(names[c], 48)}{gap}{env}", fontsize=9, loc="left")
        zoom = f"zoom {t[z0]:.2f}–{t[z1 - 1]:.2f} s"
        axz.set_title(f"{zoom}: largest held-out\n|measured − nominal| at {t[peak]:.3f} s" if c == 0 else zoom,
                      fontsize=8)
        if z1 > z0:
            axz.set_xlim(t[z0], t[z1 - 1])
        if n:
            axf.set_xlim(t[0], t[-1] + 1 / tr.fs)
    fig.legend(*axes[0, 0].get_legend_handles_labels(), fontsize=8, ncol=5, loc="outside lower center",
               frameon=False)
    t0 = f"{tr.t0:.3f}" if abs(tr.t0) >= 1e6 else f"{tr.t0:g}"
    axes[-1, 0].set_xlabel(f"time since t0 = {t0} s [s]")
    axes[-1, 1].set_xlabel("time [s]")
    log = f" — {short_label(Path(tr.log).name, 40)}" if tr.log else ""
    fig.suptitle(f"Measured vs nominal vs augmented model ({report.model_name or 'model'}, fs = {tr.fs:g} Hz){log}",
                 fontsize=10)
    return fig


def focus_band(report, frequencies) -> tuple[float, float]:
    """The frequency range the gap figures show (Hz): the located bands widened by a factor
    1.6 on each side (a band of at least a tenth of the largest band edge), else the input's
    excited band, clipped to `frequencies` (Hz; 0 to Nyquist only when nothing is known)."""
    f = np.asarray(frequencies, dtype=float)
    f0, f1 = (float(f[1]) if f.size > 1 else 0.0), float(f[-1]) if f.size else 1.0
    bands = [b for b in getattr(report, "bands", ()) if np.isfinite(b.fmin) and np.isfinite(b.fmax)]
    if bands:
        lo = min(b.fmin for b in bands)
        hi = max(b.fmax for b in bands)
        lo, hi = lo / 1.6, hi * 1.6
        if hi - lo < 0.1 * hi:
            lo = max(hi * 0.9, 0.0)
    else:
        eb = (getattr(report, "meta", None) or {}).get("excited_band_hz")
        if not eb:
            return (f0, f1)
        lo, hi = 0.8 * float(eb[0]), 1.1 * float(eb[1])
    lo, hi = max(lo, f0), min(hi, f1)
    return (lo, hi) if hi > lo else (f0, f1)


def _verdict_words(report) -> str:
    v = tuple(getattr(report, "verdicts", ()) or ())
    return " + ".join(v) if len(v) > 1 else report.verdict


def plot_gap_frf(report, *, fig=None):
    """Bode plots of the measured H1, the nominal and the augmented model, per output.

    Columns are the outputs; rows |H| in dB (re 1 output unit per unit of the first input: N, or a closed loop's reference unit),
    phase in degrees, and the coherence γ² of the measured H1.

    Parameters
    ----------
    report : GapReport
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.

    Returns
    -------
    matplotlib.figure.Figure or None
        None when the report has no spectrum (or no FRF frequencies).
    """
    sp = report.spectrum
    if sp is None or np.asarray(sp.frf_frequencies).size == 0:
        return None
    f = np.asarray(sp.frf_frequencies, dtype=float)
    Hm = np.asarray(sp.frf_measured).reshape(f.size, -1)
    Hn = np.asarray(sp.frf_nominal).reshape(f.size, -1)
    Ha = np.asarray(sp.frf_augmented).reshape(f.size, -1)
    coh = np.asarray(sp.coherence, dtype=float).reshape(f.size, -1)
    iu = _input_unit(report)
    n_out = Hm.shape[1]
    names = _channel_names(report, n_out)
    units = _units(report, n_out)
    fig = _new_figure((min(5.2 * n_out + 1.0, 16), 7.2), fig)
    axes = fig.subplots(3, n_out, squeeze=False, sharex="col", gridspec_kw={"height_ratios": [2.2, 1.3, 1]})
    lo, hi = focus_band(report, f)
    inb = (f >= lo) & (f <= hi)
    for o in range(n_out):
        axm, axp, axc = axes[:, o]
        for b in report.bands:
            for a in (axm, axp, axc):
                a.axvspan(b.fmin, b.fmax, color=BAND, alpha=0.12, lw=0, zorder=0)
        for what, H in (("measured", Hm), ("nominal", Hn), ("augmented", Ha)):
            label = {"measured": "measured H1", "nominal": "nominal model",
                     "augmented": f"augmented ({_verdict_words(report)})"}[what]
            ls = "-" if what == "measured" else "--"
            axm.plot(f, _db(H[:, o]), color=COLORS[what], lw=1.2 if what == "measured" else 1.0, ls=ls, label=label)
            axp.plot(f, np.degrees(np.angle(H[:, o])), color=COLORS[what], lw=1.0, ls=ls, label=label)
        axc.plot(f, coh[:, o], color="C0", lw=1.0, label="coherence of the measured H1")
        axm.set_ylabel(f"|H| [dB re 1 {units[o] or 'unit'}/{iu}]", fontsize=8)
        axp.set_ylabel("phase [deg]", fontsize=8)
        axp.set_ylim(-185, 185)
        axp.set_yticks([-180, -90, 0, 90, 180])
        axc.set_ylabel("coherence γ² [-]", fontsize=8)
        axc.set_ylim(-0.02, 1.05)
        axc.set_xlabel("frequency [Hz]")
        axm.set_title(f"{short_label(names[o], 40)} / first input [{iu}]", fontsize=9)
        for a in (axm, axp, axc):
            a.grid(True, alpha=0.35)
        axc.set_xlim(lo, hi)
        if inb.any():  # the magnitude axis fitted to the lines shown
            vals = np.concatenate([_db(H[inb, o]) for H in (Hm, Hn, Ha)])
            vals = vals[np.isfinite(vals)]
            if vals.size:
                axm.set_ylim(vals.min() - 3, vals.max() + 3)
        if o == 0:
            axm.legend(fontsize=7, loc="best")
    fig.suptitle(f"FRF from the first input: measured H1, nominal, augmented\n{lo:.3g}–{hi:.3g} Hz around the "
                 "located bands (shaded)", fontsize=10)
    return fig


def plot_gap_spectrum(report, *, fig=None):
    """PSD of the measured outputs and of the residuals, with the noise floor and the bands.

    One panel per output channel (log y): the measured PSD, the PSD of measured - nominal
    (before), - refitted linear model (refit) and - augmented model (after), and the
    noise-floor PSD. The frequency bands holding the gap (``report.bands``) are shaded on
    every panel and labelled with their share of the residual energy.

    Parameters
    ----------
    report : GapReport
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.

    Returns
    -------
    matplotlib.figure.Figure or None
        None when the report has no spectrum (or no frequencies).
    """
    sp = report.spectrum
    if sp is None or np.asarray(sp.frequencies).size == 0:
        return None
    import matplotlib.transforms as mtransforms

    f = np.asarray(sp.frequencies, dtype=float)
    n_ch = np.atleast_2d(sp.measured).shape[0]
    names = _channel_names(report, n_ch)
    units = _units(report, n_ch)
    fig = _new_figure((10, 1.4 + 3.0 * n_ch), fig)
    axes = np.atleast_1d(fig.subplots(n_ch, 1, squeeze=False, sharex=True).ravel())
    curves = (("measured", sp.measured, COLORS["measured"], "-", 1.1),
              ("residual before (nominal)", sp.residual_before, COLORS["nominal"], "-", 1.0),
              ("residual refit (linear)", sp.residual_refit, COLORS["refit"], "--", 1.0),
              (f"residual after (augmented: {_verdict_words(report)})", sp.residual_after, COLORS["augmented"], "-", 1.0),
              ("noise floor", sp.noise, COLORS["noise"], ":", 1.4))
    if getattr(sp, "residual_before_coherent", None) is not None:
        # the nominal residual's part coherent with the input: a gap far above it is not a linear
        # function of the input (noise of any colour, an unlogged disturbance, a distortion)
        curves = curves + (("residual before, coherent with the input", sp.residual_before_coherent,
                            COLORS["nominal"], "-.", 0.8),)
    f_lo, f_hi = focus_band(report, f)
    shown = (f >= f_lo) & (f <= f_hi)  # the y range is the shown band's (EMPS: 7e-33 m^2/Hz at 480 Hz)
    if not shown.any():
        shown = np.ones(f.size, bool)
    for c, ax in enumerate(axes):
        for k, b in enumerate(report.bands):
            ax.axvspan(b.fmin, b.fmax, color=BAND, alpha=0.14, lw=0, zorder=0,
                       label="gap bands (share of the nominal residual)" if k == 0 else None)
            tr = mtransforms.blended_transform_factory(ax.transData, ax.transAxes)
            ax.text(0.5 * (b.fmin + b.fmax), 0.985, f"{100 * b.share:.0f} %", transform=tr, ha="center",
                    va="top", fontsize=8, color=BAND, fontweight="bold", clip_on=True, zorder=5,
                    bbox=dict(boxstyle="round,pad=0.15", facecolor="white", edgecolor="none", alpha=0.8))
        ys = [_positive(np.atleast_2d(v)[c]) for _, v, *_ in curves]
        for (label, _, col, ls, lw), y in zip(curves, ys):
            ax.semilogy(f, y, color=col, ls=ls, lw=lw, label=label)
        finite = np.concatenate([y[shown] for y in ys])
        finite = finite[np.isfinite(finite)]
        if finite.size and report.bands:  # headroom for the band labels above the curves
            lo, hi = float(finite.min()), float(finite.max())
            span = np.log10(hi / lo) if hi > lo else 1.0
            ax.set_ylim(lo / 10 ** (0.05 * span), hi * 10 ** (0.16 * span))
        ax.set_ylabel(f"PSD [{_psd_unit(units[c])}]", fontsize=8)
        cg = _channel_gap(report, names[c])
        gap = f" (held-out nrmse {_fmt(cg.gap)} → {_fmt(cg.gap_after)})" if cg else ""
        ax.set_title(f"{short_label(names[c], 48)}{gap}", fontsize=9, loc="left")
        ax.grid(True, which="major", alpha=0.35)
        ax.grid(True, which="minor", alpha=0.1)
        ax.set_xlim(f_lo, f_hi)
    fig.legend(*axes[0].get_legend_handles_labels(), fontsize=8, ncol=3, loc="outside lower center", frameon=False)
    axes[-1].set_xlabel("frequency [Hz]")
    bands = ", ".join(f"{b.fmin:.3g}–{b.fmax:.3g} Hz" for b in report.bands) or "none located"
    fig.suptitle(f"Where the gap lies in frequency — bands: {bands}", fontsize=10)
    return fig


def plot_gap_evidence(report, *, fig=None):
    """One panel per signature test that carries an evidence curve (``x``, ``y``).

    Flagged tests are drawn in red on a tinted panel; the title is the test's name and
    detail, the legend gives the statistic against its threshold and the effects it points to.

    Parameters
    ----------
    report : GapReport
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.

    Returns
    -------
    matplotlib.figure.Figure or None
        None when no test has an evidence curve.
    """
    tests = [s for s in report.signatures
             if s.x is not None and s.y is not None and np.asarray(s.x).size and np.asarray(s.y).size]
    if not tests:
        return None
    from matplotlib.ticker import MaxNLocator

    n = len(tests)
    ncols = min(n, 3)
    nrows = int(np.ceil(n / ncols))
    fig = _new_figure((min(4.6 * ncols + 0.6, 16), 3.3 * nrows + 0.7), fig)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False).ravel())
    for ax, s in zip(axes, tests):
        x = np.asarray(s.x, dtype=float).ravel()
        y = np.asarray(s.y, dtype=float).ravel()
        m = min(x.size, y.size)
        col = "C3" if s.flagged else "C0"
        verdict = f"flagged: {_fmt(s.value, '.3g')} > {_fmt(s.threshold, '.3g')}" if s.flagged else \
            f"not flagged: {_fmt(s.value, '.3g')} ≤ {_fmt(s.threshold, '.3g')}"
        if s.flagged and s.points_to:
            # at most three names a line: the legend stays inside its panel
            names = list(s.points_to)
            verdict += "\n→ " + ",\n   ".join(", ".join(names[i:i + 3]) for i in range(0, len(names), 3))
        ax.plot(x[:m], y[:m], "o-" if m <= 60 else "-", color=col, ms=3, lw=1.6 if s.flagged else 1.0,
                label=verdict)
        if np.nanmin(y[:m], initial=np.inf) < 0 < np.nanmax(y[:m], initial=-np.inf):
            ax.axhline(0, color="0.5", lw=0.7)
        if s.flagged:
            ax.set_facecolor("#fdecea")
            for sp in ax.spines.values():
                sp.set_edgecolor("C3")
                sp.set_linewidth(1.4)
        ax.set_xlabel(s.x_label or "x", fontsize=8)
        ax.set_ylabel(s.y_label or "y", fontsize=8)
        title = s.name + (f": {s.detail}" if s.detail else "")
        ax.set_title(textwrap.fill(title, 52), fontsize=8, color="C3" if s.flagged else "k",
                     fontweight="bold" if s.flagged else "normal")
        ax.grid(True, alpha=0.35)
        ax.xaxis.set_major_locator(MaxNLocator(nbins=6))
        ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 4), useMathText=True)
        ax.legend(fontsize=7, loc="best")
    for ax in axes[n:]:
        ax.set_visible(False)
    n_flag = sum(bool(s.flagged) for s in tests)
    fig.suptitle(f"Signature tests on the residual of the refitted linear model ({n_flag} of {n} flagged)",
                 fontsize=10)
    return fig


def plot_gap_candidates(report, *, fig=None):
    """Held-out gap (nrmse) of every candidate effect as horizontal bars, best first.

    Vertical lines mark the nominal model's gap, the refitted linear model's gap and the noise
    floor; the verdict's bar is highlighted. Bars are labelled ``"effect @ where"``
    (:func:`candidate_label`) and with their value and score; a candidate whose fit failed
    (non-finite gap) gets a hatched full-width bar marked "failed".

    Parameters
    ----------
    report : GapReport
    fig : matplotlib.figure.Figure, optional
        Figure to draw in (cleared); a new one when None.

    Returns
    -------
    matplotlib.figure.Figure or None
        None when no candidate was tried.
    """
    cands = list(report.candidates)
    if not cands:
        return None
    from matplotlib.patches import Patch

    n = len(cands)
    g = np.array([float(c.gap_after) for c in cands], dtype=float)
    fin = np.isfinite(g)
    refs = [float(x) for x in (report.gap_before, report.gap_refit, report.noise_floor) if np.isfinite(x)]
    top = max([*g[fin].tolist(), *refs, 1e-12]) * 1.25
    widths = np.where(fin, g, top)
    vi = verdict_index(report)
    colors = [BAR_VERDICT if k == vi else BAR for k in range(n)]
    fig = _new_figure((9, max(3.6, 1.7 + 0.34 * n)), fig)
    ax = fig.subplots()
    y = np.arange(n)
    bars = ax.barh(y, widths, color=colors, edgecolor=["k" if k == vi else "none" for k in range(n)],
                   height=0.7, zorder=2)
    for k, b in enumerate(bars):
        b.set_gid(f"candidate_{k}")
        if not fin[k]:
            b.set_hatch("//")
            b.set_facecolor("0.85")
        score = f"  (score {float(cands[k].score):+.2f})" if np.isfinite(float(cands[k].score)) else ""
        ax.text(widths[k], y[k], f" {_fmt(g[k], '.4f')}{score}" if fin[k] else " failed", va="center", fontsize=7,
                fontweight="bold" if k == vi else "normal", clip_on=False)
    n_added = max(len(tuple(getattr(report, "verdicts", ()) or ())) - 1, 0)  # forward selection's additions
    added = set(range(1, 1 + n_added)) if vi == 0 else set()
    for k in added:  # an added effect's bar is the combined model's gap
        bars[k].set_facecolor(BAR_VERDICT)
        bars[k].set_alpha(0.55)
        bars[k].set_edgecolor("k")
    ax.set_yticks(y, [("+ " if k in added else "") + short_label(candidate_label(c), 48, keep="start") for k, c in enumerate(cands)],
                  fontsize=8)
    for k, lab in enumerate(ax.get_yticklabels()):
        if k == vi:
            lab.set_fontweight("bold")
    ax.invert_yaxis()  # best first, on top
    lines = (("nominal model", report.gap_before, COLORS["nominal"], "--"),
             ("refitted linear model", report.gap_refit, COLORS["refit"], "-."),
             ("noise floor", report.noise_floor, COLORS["noise"], ":"))
    handles = []
    for label, x, col, ls in lines:
        if x is not None and np.isfinite(float(x)):
            handles.append(ax.axvline(float(x), color=col, ls=ls, lw=1.5, zorder=3,
                                      label=f"{label} {float(x):.4f}"))
    handles = [Patch(facecolor=BAR_VERDICT, edgecolor="k", label=f"verdict: {report.verdict}"),
               *([Patch(facecolor=BAR_VERDICT, alpha=0.55, edgecolor="k",
                        label="+ added by forward selection (gap of the combination)")] if added else []),
               Patch(facecolor=BAR, label="other candidates"), *handles]
    fig.legend(handles=handles, fontsize=8, ncol=3, loc="outside lower center", frameon=False)
    ax.set_xlim(0, top * 1.12)
    ax.set_xlabel(f"held-out gap, {report.metric or 'nrmse'} [-] (lower is better)")
    ax.grid(True, axis="x", alpha=0.35, zorder=0)
    fig.suptitle(f"Candidate effects on held-out data — verdict {_verdict_words(report)}, "
                 f"gap {_fmt(report.gap_before, '.4f')} → {_fmt(report.gap_after, '.4f')} "
                 f"(shrink {_fmt(100 * report.shrink, '.1f')} %)", fontsize=10)
    return fig


def plot_gap_levels(report, *, fig=None):
    """The BLA per excitation level (the report's ``level_evidence``,
    :func:`plot_level_evidence`); None when the logs hold a single level."""
    ev = getattr(report, "level_evidence", None)
    if ev is None or len(ev.levels) < 2:
        return None
    return plot_level_evidence(ev, input_unit=_input_unit(report))


_PLOTTERS = {"gap_levels": plot_gap_levels, "gap_time": plot_gap_time, "gap_frf": plot_gap_frf, "gap_spectrum": plot_gap_spectrum,
             "gap_evidence": plot_gap_evidence, "gap_candidates": plot_gap_candidates}


def plot_gap_report(report, out_dir: str | Path | None = None, *,
                    names: Sequence[str] | None = None) -> dict[str, Any]:
    """Every figure of a gap diagnosis that the report has the data for.

    Parameters
    ----------
    report : GapReport
    out_dir : str or Path, optional
        Also write each figure as ``NAME.png`` there (created if missing); the written figures
        are closed in pyplot (the returned objects stay usable).
    names : sequence of str, optional
        Only these figures (of :data:`FIGURES`); all when None.

    Returns
    -------
    dict
        ``name -> matplotlib.figure.Figure``, in the order of :data:`FIGURES`; a figure whose
        data the report lacks (no traces, no spectrum, no evidence curve, no candidate) is
        left out.
    """
    wanted = FIGURES if names is None else tuple(names)
    bad = [n for n in wanted if n not in _PLOTTERS]
    if bad:
        raise ValueError(f"unknown gap figure(s) {bad}; known: {list(FIGURES)}")
    out = None
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
    figs: dict[str, Any] = {}
    for name in FIGURES:
        if name not in wanted:
            continue
        fig = _PLOTTERS[name](report)
        if fig is None:
            continue
        figs[name] = fig
        if out is not None:
            save_figure(fig, out / f"{name}.png")
    return figs


# --------------------------------------------------------------------------------------------
# level dependence of the BLA (:func:`vibroscope.gap.levels.level_blas`)
# --------------------------------------------------------------------------------------------

def plot_level_evidence(evidence, ax=None, *, out_path: str | Path | None = None, input_unit: str = "N"):
    """|H| per excitation level, and each mode's natural frequency and damping ratio vs level.

    Parameters
    ----------
    evidence : vibroscope.gap.levels.LevelEvidence
    ax : sequence of 3 matplotlib Axes, optional
        Where to draw: |H| (dB) per level, ``f_n`` vs input RMS, ``zeta`` vs input RMS; default
        a new figure (|H| on top, the two parameter panels below).
    out_path : str or Path, optional
        Write the figure as a PNG there (and close it).
    input_unit : str, optional
        Unit of the first input (default ``"N"``; a closed loop's reference: ``"m"``, ...).

    Returns
    -------
    matplotlib.figure.Figure
        (or the written Path with `out_path`).

    Notes
    -----
    Top: ``20 log10 |H1|`` of the output fitted for the first mode, one curve per level
    (lowest dark blue to highest orange), within the band around the modes (+-20 % of the outermost
    natural frequencies, clipped to the analysed band). Bottom: per mode, the relative change
    of ``f_n`` from its lowest fitted level (%) and ``zeta`` against the input RMS (log axis)
    with +-1 standard deviation error bars; the title states the test's verdict.
    """
    plt = pyplot()
    if ax is None:
        fig = plt.figure(figsize=(9.5, 7.0), layout="constrained")
        gs = fig.add_gridspec(2, 2, height_ratios=[1.2, 1.0])
        axes = [fig.add_subplot(gs[0, :]), fig.add_subplot(gs[1, 0]), fig.add_subplot(gs[1, 1])]
    else:
        axes = list(ax)
        fig = axes[0].figure
    levels = evidence.levels
    modes = evidence.modes
    n_l = len(levels)
    cmap = plt.get_cmap("plasma")
    cols = [cmap(0.0 if n_l == 1 else 0.85 * i / (n_l - 1)) for i in range(n_l)]
    o = modes[0].output if modes else 0
    f_all = [m.natural_frequency for m in modes if np.isfinite(m.natural_frequency)]
    a0 = axes[0]
    for lv, c in zip(levels, cols):
        f = lv.frequencies
        sel = np.ones(f.size, bool)
        if f_all:
            sel = (f >= 0.8 * min(f_all)) & (f <= 1.2 * max(f_all))
        a0.plot(f[sel], _db(np.abs(lv.H[sel, o])), color=c, lw=1.2,
                label=f"log {lv.log + 1}" + (f", level {lv.level + 1}" if lv.level else "") + f": {lv.rms:.3g} {input_unit} RMS")
    for fm in f_all:
        a0.axvline(fm, color="0.6", lw=0.8, ls=":")
    a0.set_xlabel("frequency [Hz]")
    a0.set_ylabel(f"|H1| output {o + 1} [dB]")
    a0.grid(True, alpha=0.3)
    a0.legend(fontsize=8, loc="best")
    # the resonance-wise test (natural frequency and damping per level against their scatter), not
    # the line-wise one of the evidence figure, which can flag what this does not
    verdict = (f"resonances level dependent: {evidence.trend}" if evidence.level_dependent
               else "no resonance changes beyond its uncertainty")
    if evidence.damping_rises:
        verdict += ", damping rises"
    a0.set_title(f"BLA per excitation level ({evidence.window}, nperseg {evidence.nperseg}, "
                 f"{evidence.fs / evidence.nperseg:.3g} Hz lines) — {verdict}", fontsize=10)
    rms = np.array([lv.rms for lv in levels])
    for j, m in enumerate(modes):
        fn = np.array([lv.natural_frequencies[j] for lv in levels])
        sf = np.array([lv.natural_frequency_std[j] for lv in levels])
        ze = np.array([lv.damping_ratios[j] for lv in levels])
        sz = np.array([lv.damping_std[j] for lv in levels])
        lab = f"mode {j + 1} ({m.natural_frequency:.4g} Hz)" + (f": {m.trend}" if m.trend != "none" else "")
        ok = np.flatnonzero(np.isfinite(fn))
        f_ref = fn[ok[0]] if ok.size else np.nan  # each mode against its lowest fitted level: a 1 % shift shows
        axes[1].errorbar(rms, 100 * (fn / f_ref - 1), yerr=100 * sf / f_ref, marker="o", capsize=3, color=f"C{j}",
                         label=lab)
        axes[2].errorbar(rms, 100 * ze, yerr=100 * sz, marker="o", capsize=3, color=f"C{j}", label=lab)
    from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullLocator

    for a, yl in ((axes[1], "f_n change from the lowest level [%]"), (axes[2], "damping ratio ζ [%]")):
        a.set_xscale("log")
        if rms.size:
            # one tick per level, thinned where two levels lie within 15 % (labels would collide)
            ticks = []
            for r in np.unique(rms):
                if not ticks or r > 1.15 * ticks[-1]:
                    ticks.append(float(r))
            a.xaxis.set_major_locator(FixedLocator(ticks))
            a.xaxis.set_minor_locator(NullLocator())
            a.xaxis.set_major_formatter(FormatStrFormatter("%.3g"))
        a.set_xlabel(f"input RMS [{input_unit}]")
        a.set_ylabel(yl)
        a.grid(True, which="both", alpha=0.3)
        if modes:
            a.legend(fontsize=8, loc="best")
    if not modes:
        axes[1].text(0.5, 0.5, "no resonance found", transform=axes[1].transAxes, ha="center")
    if out_path is not None:
        path = Path(out_path)
        path.parent.mkdir(parents=True, exist_ok=True)
        return save_figure(fig, path)
    return fig
