"""Signal faults: detection, the documented action for each, and their application.

:func:`detect_faults` looks at the samples of a :class:`~vibroscope.signals.Signals` (never at
the reader's report, so it works on any source) and returns one :class:`Fault` per problem found;
:func:`apply_faults` applies the documented actions before an analysis. The rules (thresholds are
module constants):

=================  ==========================================================  ==================
kind               rule                                                        action
=================  ==========================================================  ==================
``nan``            NaN samples (missing: logging gaps, lost chunks); spans     ``skip_segments``
                   are the NaN runs. A channel with no NaN-free stretch of      (``stop`` when
                   `nperseg` samples, or all NaN, cannot be analysed.          nothing remains)
``inf``            ±Inf samples                                                ``mask``
``overflow``       finite samples beyond ±:data:`OVERFLOW_LIMIT` (no physical   ``mask``
                   quantity in SI units; their squares overflow the spectra)
``clipping``       the largest (smallest) value is held for runs of at least   ``mask``
                   :data:`CLIP_MIN_RUN` samples and occurs at least
                   :data:`CLIP_RATIO` times as often as the next distinct
                   value below (above) it: a spike in the histogram at a rail
                   (not when it holds more than :data:`CLIP_MAX_FRACTION`
                   of the samples: a level or state word)
``dropout``        a run of equal consecutive samples (zeros or a held value)  ``mask``
                   of length L ≥ :data:`DROPOUT_MIN_RUN` inside a varying
                   channel, so long that equal steps at the channel's own rate
                   p₀ would give it with odds below :data:`DROPOUT_ODDS`
                   over the record (``n p₀^(L-1)``); not when such runs hold
                   more than :data:`DROPOUT_MAX_FRACTION` of the samples
``dc_offset``      ``|mean| > DC_RATIO · std`` of the finite samples           ``detrend``
                   (not when it is gravity: see ``gravity``)
``gravity``        a note, not a fault: the ``dc_offset`` of an acceleration   ``detrend``
                   channel (m/s² or g) whose sensor's mean vector has the
                   length of standard gravity within :data:`GRAVITY_TOL`
                   (the x, y, z axes of one sensor together; one axis alone:
                   a mean near ±9.81 m/s²)
``drift``          the means of consecutive `nperseg`-blocks scatter by more   ``report``
                   than :data:`DRIFT_RATIO` times the median within-block std
                   (a trend slower than one segment, at least 4 blocks)
``missing_unit``   the channel's unit is empty                                 ``report``
``constant``       every finite sample equal (output channel; a note, not a    ``drop``
                   fault: a joint at rest, an unused axis)
``zero_input``     the input (force) channel is zero throughout                ``stop``
``constant`` input the input channel is constant but not zero                  ``stop``
``short_record``   fewer samples than `nperseg`                                ``stop``
=================  ==========================================================  ==================

A *note* (:attr:`Fault.note`) is an expected property of a signal, not a problem: it is handled
by its action like a fault, listed under ``notes`` in the analysis's JSON and printed only with
``--verbose``; :func:`fault_summary` counts the faults alone.

Actions: ``skip_segments`` — the spectral estimators skip every Welch segment that touches a
missing sample (:mod:`vibroscope.spectral`); ``mask`` — the samples of the spans become NaN
(never replaced by other numbers) and are then skipped the same way; ``detrend`` — removed by the
per-segment (constant) detrend of the spectra, reported only; ``report`` — reported, nothing
changed; ``drop`` — the channel is left out of the analysis; ``stop`` — :func:`apply_faults`
raises ``ValueError`` naming the channel and the remedy.

Duplicated or out-of-order stamps are the reader's concern (a ``Signals`` is on a uniform grid
by construction); they are not looked for here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from vibroscope.signals import Signals, true_runs
from vibroscope.spectral.integration import ACC_UNITS, G_N

__all__ = ["fault_lines", "fault_summary", "Fault", "FAULT_KINDS", "detect_faults", "apply_faults", "nan_spans"]

FAULT_KINDS = ("nan", "inf", "overflow", "clipping", "dropout", "dc_offset", "gravity", "drift", "missing_unit",
               "constant", "zero_input", "short_record")
Action = Literal["skip_segments", "mask", "detrend", "report", "drop", "stop"]

#: clipping: a rail value held for at least this many consecutive samples ...
CLIP_MIN_RUN = 3
#: ... and at least this many times as frequent as the next distinct value inside the rail
CLIP_RATIO = 4.0
#: clipping: not when the rail holds more than this fraction of the samples (a level or a state
#: word, not a clipped vibration)
CLIP_MAX_FRACTION = 0.25
#: dropout: not when the long runs hold more than this fraction of the samples (a stepped or
#: mostly idle channel, not dropouts inside a live signal)
DROPOUT_MAX_FRACTION = 0.5
#: dropout: shortest run of equal consecutive samples reported
DROPOUT_MIN_RUN = 16
#: dropout: chance odds (over the whole record) below which a run of equal samples is a fault
DROPOUT_ODDS = 1e-3
#: overflow: a finite sample beyond this magnitude is no measurement (a corrupted value: its square,
#: near 1e200 and beyond, overflows float64 spectra and covariances)
OVERFLOW_LIMIT = 1e100
#: dc_offset: |mean| larger than this many standard deviations
DC_RATIO = 1.0
#: gravity: a sensor's mean acceleration vector within this fraction of G_N is gravity (local g
#: varies by 0.5 %, MEMS accelerometers' bias and scale errors by a few %)
GRAVITY_TOL = 0.05
#: gravity: the units of acceleration channels (m/s² spellings, and g) and their scale to m/s²
_ACC_SCALE = {**dict.fromkeys(ACC_UNITS, 1.0), "g": G_N}
#: drift: std of the block means larger than this times the median within-block std
DRIFT_RATIO = 0.5
#: spans listed per fault in messages
_SHOW = 3


@dataclass(frozen=True, kw_only=True)
class Fault:
    """One problem found in one channel.

    Attributes
    ----------
    channel : str
        The channel's name.
    kind : str
        One of :data:`FAULT_KINDS`.
    message : str
        What is wrong, where, and what the analysis does about it (one line).
    action : {'skip_segments', 'mask', 'detrend', 'report', 'drop', 'stop'}
        What the analysis does (see the module docstring).
    spans : tuple of (int, int)
        Sample index ranges ``[start, stop)`` of the fault; empty for whole-channel faults.
    times : tuple of (float, float)
        The same spans in s from the first sample (``start / fs``, ``stop / fs``).
    n_samples : int
        Samples affected (0 for whole-channel faults that mark none).
    note : bool
        An expected property of the signal (gravity on an accelerometer axis, a constant output
        channel), not a problem: reported as a note, handled by its `action` all the same.
    """

    channel: str
    kind: str
    message: str
    action: Action
    spans: tuple = ()
    times: tuple = ()
    n_samples: int = 0
    note: bool = False

    def __str__(self) -> str:
        return f"{self.kind} in {self.channel}: {self.message}"

    def to_dict(self) -> dict:
        """JSON-ready dict: ``channel``, ``kind``, ``message``, ``action``, ``n_samples``,
        ``n_spans``, ``spans`` and ``times_s`` (the first 100 spans), ``note``."""
        return {"channel": self.channel, "kind": self.kind, "message": self.message, "action": self.action,
                "note": self.note,
                "n_samples": int(self.n_samples), "n_spans": len(self.spans),
                "spans": [[int(a), int(b)] for a, b in self.spans[:100]],
                "times_s": [[float(a), float(b)] for a, b in self.times[:100]]}


def fault_lines(faults, *, max_names: int = 3) -> list[str]:
    """One line per kind of fault: the channels it touches and one example message.

    Parameters
    ----------
    faults : sequence of Fault
        From :func:`detect_faults`.
    max_names : int, optional
        Channels named before "and N more"; default 3.

    Returns
    -------
    list of str
        ``"<kind> in <channel>: <message>"`` for a kind found in one channel;
        ``"<kind> in N channels (<a>, <b>, <c> and M more); e.g. <a>: <message>"`` otherwise, in
        the order the kinds first occur. Every fault stays in full in ``Analysis.faults`` and the
        JSON summary.
    """
    by_kind: dict[str, list] = {}
    for f in faults:
        by_kind.setdefault(f.kind, []).append(f)
    out = []
    for kind, fs in by_kind.items():
        if len(fs) == 1:
            out.append(str(fs[0]))
            continue
        names = ", ".join(f.channel for f in fs[:max_names])
        more = f" and {len(fs) - max_names} more" if len(fs) > max_names else ""
        out.append(f"{kind} in {len(fs)} channels ({names}{more}); e.g. {fs[0].channel}: {fs[0].message}")
    return out


def fault_summary(faults) -> str:
    """One line counting the faults (not the notes) per kind, the most frequent first.

    Parameters
    ----------
    faults : sequence of Fault
        From :func:`detect_faults`; notes (:attr:`Fault.note`) are not counted.

    Returns
    -------
    str
        ``"2 dropout, 1 clipping"`` (channels per kind; kinds with equal counts in the order they
        first occur), or ``""`` when there is no fault.

    Examples
    --------
    >>> def fault(channel, kind, action="mask", note=False):
    ...     return Fault(channel=channel, kind=kind, message="", action=action, note=note)
    >>> fault_summary([fault("a", "dropout"), fault("b", "clipping"), fault("b", "dropout"),
    ...                fault("c", "gravity", "detrend", note=True)])
    '2 dropout, 1 clipping'
    """
    counts: dict[str, int] = {}
    for f in faults:
        if not f.note:
            counts[f.kind] = counts.get(f.kind, 0) + 1
    order = sorted(counts, key=lambda k: -counts[k])  # stable: ties keep their first occurrence
    return ", ".join(f"{counts[k]} {k}" for k in order)


def nan_spans(x: np.ndarray) -> list[tuple[int, int]]:
    """Runs of non-finite samples (NaN or ±Inf) of a 1-D record, as ``[start, stop)`` index pairs.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
        The samples.

    Returns
    -------
    list of (int, int)
        Sample index ranges, in order; empty when every sample is finite.
    """
    a, b = true_runs(~np.isfinite(np.asarray(x, dtype=float)))
    return list(zip(a.tolist(), b.tolist()))


def _where(spans, fs: float) -> str:
    shown = ", ".join(f"{a / fs:.4g}–{b / fs:.4g} s" for a, b in spans[:_SHOW])
    more = f" and {len(spans) - _SHOW} more" if len(spans) > _SHOW else ""
    return f"{len(spans)} span{'s' if len(spans) != 1 else ''} ({shown}{more})"


def _fault(ch, kind, msg, action, spans, fs, n, note=False):
    spans = tuple((int(a), int(b)) for a, b in spans)
    return Fault(channel=ch, kind=kind, message=msg, action=action, spans=spans,
                 times=tuple((a / fs, b / fs) for a, b in spans),
                 n_samples=int(n), note=note)


def _sensor(channel: str) -> str:
    """The sensor an axis belongs to: the channel without a last ``.x``/``.y``/``.z``."""
    head, dot, axis = channel.rpartition(".")
    return head if dot and axis in ("x", "y", "z") else channel


def _gravity(signals: Signals, means: dict) -> dict:
    """The acceleration channels whose offset is gravity, with the length of their sensor's mean
    vector (m/s²): the axes of one sensor (:func:`_sensor`) together."""
    by_sensor: dict[str, list] = {}
    for ch, unit in zip(signals.channels, signals.units):
        scale = _ACC_SCALE.get(unit.strip())
        if scale is not None and ch in means:
            by_sensor.setdefault((_sensor(ch), unit.strip()), []).append((ch, means[ch] * scale))
    out = {}
    for axes in by_sensor.values():
        norm = float(np.sqrt(sum(m * m for _, m in axes)))
        if abs(norm - G_N) <= GRAVITY_TOL * G_N:
            out.update({ch: norm for ch, _ in axes})
    return out


def _clipping(x: np.ndarray, finite: np.ndarray) -> list[tuple[int, int, float]]:
    """Runs at a clipped rail: (start, stop, rail value)."""
    out = []
    xf = x if finite.all() else x[finite]
    if xf.size < 2 * CLIP_MIN_RUN:
        return out
    for sign in (1.0, -1.0):
        v = xf.max() if sign > 0 else xf.min()
        at = x == v
        n_at = int(np.count_nonzero(at))
        if n_at < CLIP_MIN_RUN or n_at > CLIP_MAX_FRACTION * xf.size:
            continue
        inside = xf[xf < v] if sign > 0 else xf[xf > v]
        if inside.size == 0:
            continue  # constant channel
        nxt = inside.max() if sign > 0 else inside.min()
        n_next = int(np.count_nonzero(xf == nxt))
        a, b = true_runs(at)
        if n_at < CLIP_RATIO * n_next or not np.any(b - a >= CLIP_MIN_RUN):
            continue
        out += [(int(s), int(e), float(v)) for s, e in zip(a, b)]
    return out


def _dropouts(x: np.ndarray, finite: np.ndarray, rails: set) -> list[tuple[int, int, float]]:
    """Runs of equal consecutive samples too long to be chance: (start, stop, value)."""
    n = x.size
    if n < DROPOUT_MIN_RUN:
        return []
    eq = x[1:] == x[:-1]  # NaN never equals; Inf runs are the 'inf' fault's
    if not finite.all():
        eq &= finite[1:]
    if not eq.any():
        return []
    a, b = true_runs(eq)  # a run of k equal steps is k + 1 equal samples
    lengths = b - a + 1
    long = lengths >= DROPOUT_MIN_RUN
    # the channel's own rate of equal steps, outside the long runs (quantised data repeat often)
    steps = max(1, int(np.count_nonzero(finite[1:] & finite[:-1])) - int((lengths[long] - 1).sum()))
    p0 = (int(eq.sum()) - int((lengths[long] - 1).sum())) / steps
    if p0 >= 0.5:
        return []  # barely varying (coarsely quantised) channel: runs are not evidence
    L = DROPOUT_MIN_RUN if p0 <= 0 else max(DROPOUT_MIN_RUN, int(np.ceil(1 + np.log(DROPOUT_ODDS / n) / np.log(p0))))
    out = [(int(s), int(e) + 1, float(x[s])) for s, e, ln in zip(a, b, lengths)
           if ln >= L and float(x[s]) not in rails]
    if sum(e - s for s, e, _ in out) > DROPOUT_MAX_FRACTION * int(np.count_nonzero(finite)):
        return []  # mostly held: a stepped or idle channel, not a live one
    return out


def detect_faults(signals: Signals, *, input: str | None = None, nperseg: int | None = None) -> tuple[Fault, ...]:
    """Find missing samples, clipping, dropouts, offsets, drift, missing units, constant and
    zero channels and a record too short, channel by channel.

    Parameters
    ----------
    signals : Signals
        The record.
    input : str, optional
        The force (input) channel, whose zero or constant content stops an FRF analysis.
    nperseg : int, optional
        The Welch segment length the analysis will use (short records, NaN-free stretches, the
        drift blocks); default ``max(16, n_samples // 16)``.

    Returns
    -------
    tuple of Fault
        In channel order, then by kind; empty for a clean record. The rules and actions are in
        the module docstring; the notes among them (gravity, a constant output) have
        :attr:`Fault.note` set.

    Raises
    ------
    KeyError
        If `input` is not a channel of `signals`.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(0).standard_normal((1, 4096))
    >>> x[0, 100:110] = np.nan
    >>> [f.kind for f in detect_faults(Signals(data=x, fs=100.0, channels=["a"], units=["m/s^2"]))]
    ['nan']
    """
    fs, n = signals.fs, signals.n_samples
    if input is not None:
        signals.index(input)
    nper = int(nperseg) if nperseg is not None else max(16, n // 16)
    faults: list[Fault] = []
    with np.errstate(all="ignore"):  # an all-missing or overflowing channel has no mean: no gravity
        means = {ch: float(np.nanmean(np.where(np.abs(x) <= OVERFLOW_LIMIT, x, np.nan)))
                 for ch, unit, x in zip(signals.channels, signals.units, signals.data)
                 if unit.strip() in _ACC_SCALE and np.isfinite(x).any()}
    gravity = _gravity(signals, means)
    if n < nper:
        for ch in signals.channels:
            faults.append(_fault(ch, "short_record",
                                 f"{n} samples ({n / fs:.4g} s) is shorter than nperseg={nper}: "
                                 f"use a shorter nperseg or a longer record", "stop", (), fs, 0))
    for ch, unit, x in zip(signals.channels, signals.units, signals.data):
        is_input = ch == input
        finite = np.isfinite(x)
        all_finite = bool(finite.all())
        nan = np.zeros(1, bool) if all_finite else np.isnan(x)
        inf = np.zeros(1, bool) if all_finite else np.isinf(x)
        n_fin = int(np.count_nonzero(finite))
        if nan.any():
            spans = nan_spans(np.where(inf, 0.0, x))
            if n_fin == 0:
                faults.append(_fault(ch, "nan", "every sample is missing (NaN): nothing to analyse; "
                                     "drop the channel or check the log", "stop", spans, fs, nan.sum()))
                continue
            a, b = true_runs(finite)
            longest = int((b - a).max())
            if longest < nper:
                faults.append(_fault(ch, "nan", f"{int(nan.sum())} missing samples (NaN) in {_where(spans, fs)}; "
                                     f"the longest stretch without one is {longest} samples < nperseg={nper}: "
                                     f"use a shorter nperseg", "stop", spans, fs, nan.sum()))
            else:
                faults.append(_fault(ch, "nan", f"{int(nan.sum())} missing samples (NaN) in {_where(spans, fs)}; "
                                     f"Welch segments touching them are skipped", "skip_segments", spans, fs,
                                     nan.sum()))
        if inf.any():
            a, b = true_runs(inf)
            spans = list(zip(a, b))
            faults.append(_fault(ch, "inf", f"{int(inf.sum())} infinite samples in {_where(spans, fs)}; "
                                 f"treated as missing (NaN), their segments skipped", "mask", spans, fs, inf.sum()))
        huge = finite & (np.abs(np.where(finite, x, 0.0)) > OVERFLOW_LIMIT)
        if huge.any():
            a, b = true_runs(huge)
            spans = list(zip(a, b))
            big = float(np.abs(x[huge]).max())
            faults.append(_fault(ch, "overflow", f"{int(huge.sum())} samples beyond ±{OVERFLOW_LIMIT:.0e} (up to "
                                 f"{big:.3g}) in {_where(spans, fs)}: no measurement; treated as missing (NaN), their "
                                 f"segments skipped", "mask", spans, fs, huge.sum()))
            finite = finite & ~huge
            x = np.where(huge, np.nan, x)  # the checks below see them as missing, as the analysis will
            all_finite = False
            n_fin = int(np.count_nonzero(finite))
        if n_fin == 0:
            continue
        xf = x if all_finite else x[finite]
        lo, hi = float(xf.min()), float(xf.max())
        if hi == lo:
            if is_input and hi == 0:
                faults.append(_fault(ch, "zero_input", "the input (force) channel is zero throughout: no "
                                     "excitation, no FRF; check the force sensor or analyse output-only "
                                     "(without --input)", "stop", (), fs, 0))
            elif is_input:
                faults.append(_fault(ch, "constant", f"the input (force) channel is constant ({hi:.6g}): no "
                                     f"excitation, no FRF; check the force sensor or analyse output-only "
                                     f"(without --input)", "stop", (), fs, 0))
            else:
                faults.append(_fault(ch, "constant", f"constant ({hi:.6g}) throughout: no vibration, left out "
                                     f"of the analysis", "drop", (), fs, 0, note=True))
            continue
        if not unit:
            faults.append(_fault(ch, "missing_unit", "no unit: spectra are in unit²/Hz of an unknown unit and "
                                 "the FRF kind cannot be inferred; store units in the log (vibroscope convert --units)", "report", (), fs, 0))
        clip = _clipping(x, finite)
        if clip:
            spans = [(a, b) for a, b, _ in clip]
            rails = sorted({v for _, _, v in clip})
            k = sum(b - a for a, b in spans)
            faults.append(_fault(ch, "clipping", f"{k} samples at the rail{'s' if len(rails) > 1 else ''} "
                                 f"{', '.join(f'{v:.6g}' for v in rails)} (flat tops) in {_where(spans, fs)}; "
                                 f"masked as missing, their segments skipped: reduce the gain or use a "
                                 f"larger range", "mask", spans, fs, k))
        drop = _dropouts(x, finite, {v for _, _, v in clip})
        if drop:
            spans = [(a, b) for a, b, _ in drop]
            k = sum(b - a for a, b in spans)
            vals = {v for _, _, v in drop}
            what = "zeros" if vals == {0.0} else "a held value"
            faults.append(_fault(ch, "dropout", f"{k} samples of {what} in {_where(spans, fs)} inside a live "
                                 f"signal; masked as missing, their segments skipped", "mask", spans, fs, k))
        mean, std = float(xf.mean()), float(xf.std())
        if abs(mean) > DC_RATIO * std and ch in gravity:
            faults.append(_fault(ch, "gravity", f"mean {mean:.4g} {unit}: gravity (the sensor's mean acceleration "
                                 f"is {gravity[ch]:.4g} m/s², g = {G_N} m/s²); removed by the per-segment "
                                 f"detrend", "detrend", (), fs, 0, note=True))
        elif abs(mean) > DC_RATIO * std:
            faults.append(_fault(ch, "dc_offset", f"mean {mean:.4g} is {abs(mean) / std:.3g} standard deviations "
                                 f"({std:.4g}); removed by the per-segment detrend", "detrend", (), fs, 0))
        drift = _drift(x, nper)
        if drift is not None:
            faults.append(_fault(ch, "drift", f"slow trend: the means of {nper}-sample blocks scatter by "
                                 f"{drift:.3g} times the fluctuation within a block; spectra below "
                                 f"{fs / nper:.3g} Hz are unreliable: high-pass filter the record or use "
                                 f"detrend='linear'", "report", (), fs, 0))
    return tuple(faults)


def _drift(x: np.ndarray, nper: int) -> float | None:
    """Ratio of the block means' std to the median block std when above :data:`DRIFT_RATIO`."""
    k = x.size // nper
    if k < 4:
        return None
    blocks = x[: k * nper].reshape(k, nper)
    ok = np.isfinite(blocks).all(axis=1)
    if ok.sum() < 4:
        return None
    b = blocks[ok]
    within = float(np.median(b.std(axis=1)))
    if within == 0:
        return None
    ratio = float(b.mean(axis=1).std()) / within
    return ratio if ratio > DRIFT_RATIO else None


def apply_faults(signals: Signals, faults: tuple[Fault, ...] | list[Fault]) -> Signals:
    """Apply the documented actions: mask spans as NaN, drop constant channels, stop on fatal ones.

    Parameters
    ----------
    signals : Signals
        The record the faults were detected in.
    faults : sequence of Fault
        From :func:`detect_faults` on `signals`.

    Returns
    -------
    Signals
        The record with the ``mask`` spans (Inf, overflow, clipping, dropouts) set to NaN and the ``drop``
        channels removed; `signals` itself when nothing changes. Never a replaced sample: a
        masked one is NaN.

    Raises
    ------
    ValueError
        At the first fault whose action is ``stop``; the message names the channel and the
        remedy (:meth:`Fault.__str__`).
    """
    for f in faults:
        if f.action == "stop":
            raise ValueError(str(f))
    masks = [f for f in faults if f.action == "mask"]
    drops = [f.channel for f in faults if f.action == "drop"]
    out = signals
    if masks:
        data = np.array(signals.data)
        for f in masks:
            i = signals.index(f.channel)
            for a, b in f.spans:
                data[i, a:b] = np.nan
        out = Signals(data=data, fs=signals.fs, channels=signals.channels, units=signals.units, t0=signals.t0,
                      meta=signals.meta)
    if drops:
        keep = [c for c in out.channels if c not in set(drops)]
        out = out.select(keep)
    return out
