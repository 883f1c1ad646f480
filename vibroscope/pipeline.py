"""The analyser's composition: Signals → spectra, FRFs, coherence, modal vectors → summary.

This module chooses settings and calls the numerical rooms (:mod:`vibroscope.spectral`,
:mod:`vibroscope.modal`); it holds no numerics of its own. :mod:`vibroscope.commands.analyse`
adds the edges (reading MCAP, writing rerun recordings and figures).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Sequence

import numpy as np
import scipy.signal

from vibroscope._checks import jsonable
from vibroscope.faults import apply_faults, detect_faults
from vibroscope.signals import Signals, true_runs
from vibroscope.spectral import FRF, CrossSpectralMatrix, Spectrum, csd_matrix, frf
from vibroscope.spectral.estimators import MIN_AVERAGES, FewAveragesWarning
from vibroscope.modal.methods import METHOD_CHOICES, MODAL_METHODS, identify, resolve_method
from vibroscope.modal.selection import excited_band, response_band

__all__ = ["Analysis", "AnalysisPlan", "IdentifySettings", "METHODS", "analyse_signals", "decimate", "decimation_stages", "default_nperseg",
           "summary_dict"]


@dataclass(frozen=True, kw_only=True)
class AnalysisPlan:
    """The settings of one analysis, chosen once from the prepared record before the pass that
    identifies the modes (:func:`analyse_signals`; printed by the report, under ``plan`` in the summary);
    only the damping refinement of the segment, which needs the identified modes, is recorded after it.

    Attributes
    ----------
    input : str or None
        The force channel; None for an output-only analysis.
    outputs : tuple of str
        The response channels analysed (constant ones already left out).
    fs_in : float
        Rate of the record in Hz.
    fs : float
        Rate analysed in Hz (after any decimation).
    factors : tuple of int
        The decimation's stages (:func:`decimation_stages`); empty when not decimated.
    decimation_reason : str or None
        Why this decimation (or why none); None when decimating would not gain.
    fmin : float or None
        Lower edge (Hz) of the band searched for modes, as asked.
    fmax : float
        Upper edge (Hz) of that band (asked, or chosen from the data, else ``0.4 fs``).
    band : tuple of (float or None, float)
        The band (Hz) the modes are selected in (with an input: the excited band within
        `fmin`, `fmax`).
    f_low : float or None
        Output-only: the lowest resonance (Hz) found in the response; it sets the SSI / polyMAX lags.
    period : int or None
        Period in samples (at `fs`) of a periodic input: the FRFs are period-synchronous.
    nperseg : int
        The planned Welch segment length; with an input and the automatic length the
        identification may refine it for the damping (`nperseg_refined`).
    window : str
        Welch window.
    estimator : str or None
        FRF estimator with an input; None output-only.
    method : str
        The identification method (the registry's result name, e.g. ``'lscf'``, ``'ssi_cov'``;
        :func:`vibroscope.modal.methods.resolve_method`).
    nperseg_refined : int or None
        The segment length the identification refined `nperseg` to for the damping (doubled
        while an identified mode's half-power band spans fewer than 8 bins); None when it was not
        refined. The one setting that follows a result of the pass (the identified modes), so it
        is recorded after it: ``Analysis.plan`` states the length used
        (``Analysis.settings["nperseg"]``).
    """

    input: str | None
    outputs: tuple
    fs_in: float
    fs: float
    factors: tuple
    decimation_reason: str | None
    fmin: float | None
    fmax: float
    band: tuple
    f_low: float | None
    period: int | None
    nperseg: int
    window: str
    estimator: str | None
    method: str
    nperseg_refined: int | None = None

    def decimation_dict(self) -> dict:
        """``Analysis.settings["decimation"]``: ``fs_in``, ``fs_out`` (Hz), ``factors``, ``reason``.

        Returns
        -------
        dict
            In the key order the summary has always written (that of ``Signals.meta["decimated"]``
            when decimated).
        """
        if self.factors:
            return {"factors": list(self.factors), "fs_in": self.fs_in, "fs_out": self.fs,
                    "reason": self.decimation_reason}
        return {"fs_in": self.fs_in, "fs_out": self.fs, "factors": [], "reason": self.decimation_reason}

    def to_dict(self) -> dict:
        """The plan as a JSON-ready dict (the summary's ``plan``).

        Returns
        -------
        dict
            The attributes by name (tuples as lists).
        """
        return jsonable({k: list(v) if isinstance(v, tuple) else v for k, v in self.__dict__.items()})

    def line(self) -> str:
        """The plan in one line of the report.

        Returns
        -------
        str
            ``"plan: 1000 → 250 Hz (factors [4]); band 2–100 Hz, modes in 2–98 Hz; nperseg 2048; ..."``
            (``nperseg 2048 → 8192 for the damping`` when the identification refined it).
        """
        rate = (f"{self.fs_in:g} → {self.fs:g} Hz (factors {list(self.factors)})" if self.factors
                else f"{self.fs:g} Hz")
        modes = (f"modes below {self.band[1]:.4g} Hz" if self.band[0] is None
                 else f"modes in {self.band[0]:.4g}–{self.band[1]:.4g} Hz")
        nps = f"nperseg {self.nperseg}"
        if self.nperseg_refined is not None:
            nps += f" → {self.nperseg_refined} for the damping"
        parts = [f"plan: {rate}", f"band up to {self.fmax:.4g} Hz, {modes}", nps, f"method {self.method}"]
        if self.f_low is not None:
            parts.append(f"lowest resonance {self.f_low:.4g} Hz")
        if self.period is not None:
            parts.append(f"input period {self.period} samples")
        return "; ".join(parts)


@dataclass(frozen=True, eq=False, kw_only=True)
class Analysis:
    """Everything one analysis produced, from the time series (:func:`analyse_signals`) or from
    spectra accumulated block by block (:func:`vibroscope.stream.analyse_stream`, `streamed`).

    Attributes
    ----------
    signals : Signals or None
        The analysed record (after any decimation), input channel first when there is one; None
        for a streamed analysis (the record is never held whole).
    psd : Spectrum
        Welch PSD of every channel (unit²/Hz).
    csd : CrossSpectralMatrix
        Cross-spectral matrix of the response channels (output-only modal analysis uses it).
    frf : FRF or None
        H1/H2/Hv estimate from the input to every response, with coherence; None without input.
    modal : ModalModel
        Natural frequencies (Hz), damping ratios, complex mode shapes over the response channels.
    singular_values : SingularValues
        Singular values of the response CSD (FDD); unpacks as ``(frequencies Hz, S (n_freqs,
        n_channels))``.
    settings : dict
        Welch settings, the band analysed and the decimation (``decimation``: ``fs_in``,
        ``fs_out``, ``factors``, ``reason``; see :func:`analyse_signals`); streamed: ``streamed``
        True and ``n_samples``.
    warnings : list of str
        What the reader and the analysis noticed (gaps, jitter, skipped channels, ...).
    identification : Identification or None
        The modes with the rejected candidates (and why), the stabilization diagram, the
        settings chosen and, for LSCF, the LSFD residues (:mod:`vibroscope.modal.automatic`).
    severity : Severity or None
        ISO 20816 vibration severity (velocity RMS over 10–1000 Hz, mm/s) of the acceleration
        channels, from the record before any decimation; None streamed.
    faults : tuple of Fault
        The signal faults found (:func:`vibroscope.faults.detect_faults`) and handled; each is
        also one line of `warnings`.
    notes : tuple of Fault
        Expected properties of the signals, handled like faults but no warning (gravity on an
        accelerometer axis, a constant output channel left out; :attr:`vibroscope.faults.Fault.note`).
    spectra : LogSpectra or None
        A streamed analysis's accumulated sums (:class:`vibroscope.stream.LogSpectra`; merge them
        with other logs' through :func:`vibroscope.stream.merge_spectra`); None for a whole read.
    plan : AnalysisPlan or None
        The settings chosen from the data before the identification (:func:`analyse_signals`);
        None streamed.
    """

    signals: Signals | None
    psd: Spectrum
    csd: CrossSpectralMatrix
    frf: FRF | None
    modal: Any
    singular_values: Any
    settings: dict
    warnings: list = field(default_factory=list)
    identification: Any = None
    severity: Any = None
    faults: tuple = ()
    notes: tuple = ()
    spectra: Any = None
    plan: AnalysisPlan | None = None

    @property
    def streamed(self) -> bool:
        """True for an analysis of accumulated spectra (no time series held)."""
        return self.signals is None

    @property
    def fs(self) -> float:
        """Rate analysed in Hz."""
        return self.signals.fs if self.signals is not None else self.spectra.fs

    @property
    def n_samples(self) -> int:
        """Samples analysed (streamed: the grid samples read)."""
        return self.signals.n_samples if self.signals is not None else self.spectra.samples

    @property
    def duration_s(self) -> float:
        """Length of the record analysed in s, ``n_samples / fs``."""
        return self.n_samples / self.fs

    @property
    def channels(self) -> tuple:
        """The channels of the record (streamed: those accumulated)."""
        return tuple(self.signals.channels if self.signals is not None else self.spectra.channels)

    @property
    def units(self) -> tuple:
        """The units of `channels`."""
        return tuple(self.signals.units if self.signals is not None else self.spectra.units)

    @property
    def input_choice(self) -> str | None:
        """The line naming the force-like channel taken as the input (or why none was), when the
        log was searched for one; else None."""
        if self.settings.get("input_choice"):
            return self.settings["input_choice"]
        return self.signals.meta.get("input_choice") if self.signals is not None else None


def default_nperseg(n: int, fs: float, *, fmin: float | None = None, averages: int = 16) -> int:
    """Segment length giving about `averages` half-overlapping segments, a power of two.

    When `fmin` (Hz) is given, the segment is lengthened if needed so that the resolution
    ``fs / nperseg`` is at most ``fmin / 8`` (a lightly damped mode near fmin still spans bins),
    down to a minimum of 4 averages.

    Parameters
    ----------
    n : int
        Record length in samples.
    fs : float
        Sampling frequency in Hz.
    fmin : float, optional
        Lowest frequency of interest in Hz; default None (no lengthening).
    averages : int, optional
        Target number of 50 %-overlapping segments; default 16.

    Returns
    -------
    int
        A power of two (at least 16), at most `n`.
    """
    target = max(16, int(2 * n / (averages + 1)))
    nper = 2 ** int(np.floor(np.log2(target)))
    if fmin:
        need = 2 ** int(np.ceil(np.log2(8 * fs / fmin)))
        nper = max(nper, min(need, 2 ** int(np.floor(np.log2(2 * n / 5)))))
    return int(min(nper, n))


def decimate(signals: Signals, fmax: float, *, period: int | None = None) -> Signals:
    """Low-pass and decimate so that `fmax` (Hz) stays below 0.4·fs; unchanged if no gain.

    Each stage of at most 10 low-passes with an order-9 Chebyshev I filter (0.05 dB ripple, edge
    at 0.8 of the new Nyquist frequency, :data:`DECIMATION_ORDER`; odd, so a mean keeps its value)
    run forwards and backwards (zero phase, :func:`scipy.signal.sosfiltfilt`), then keeps every
    factor-th sample.
    Missing samples (NaN in any channel) are never filtered across: each stretch where every
    channel is present is decimated as a record of its own, on the global decimated grid (its
    start rounded up to a multiple of the factor), and the decimated samples of the gaps (and of
    stretches too short to filter) are NaN.

    Parameters
    ----------
    signals : Signals
        The record.
    fmax : float
        Highest frequency of interest in Hz; the total factor is at most ``floor(fs / (2.5 fmax))``,
        so the reduced rate is at least ``2.5 fmax``.
    period : int, optional
        Period in samples of a periodic excitation in the record. The total factor is then the
        largest one within that bound that divides `period` and is a product of stages of at most
        10, so that the decimated record is periodic in ``period / factor`` whole samples (a
        period-synchronous FRF needs whole periods; Pintelon & Schoukens 2012, §2.2); unchanged when
        there is none. Default None (the factor ``floor(fs / (2.5 fmax))`` in stages of at most 10).

    Returns
    -------
    Signals
        At the reduced rate, with ``meta["decimated"] = {"factors", "fs_in", "fs_out", "reason"}``
        (``reason``: one line saying why this factor); the input itself when no factor of at least
        2 fits.

    Raises
    ------
    ValueError
        If `fmax` is not positive or `period` is below 2.
    """
    if not (np.isfinite(fmax) and fmax > 0):
        raise ValueError(f"{fmax=} must be a positive frequency in Hz")
    stages = decimation_stages(signals.fs, fmax, period=period)
    if not stages:
        return signals
    total = int(np.prod(stages))
    fs = signals.fs / total
    present = np.isfinite(signals.data).all(axis=0)
    if present.all():
        data = _decimate_stages(signals.data, stages)
    else:
        n_out = -(-signals.n_samples // total)
        data = np.full((signals.n_channels, n_out), np.nan)
        edges = np.flatnonzero(np.diff(np.concatenate(([0], present.astype(np.int8), [0]))))
        for a, b in zip(edges[::2], edges[1::2]):
            a = -(-a // total) * total  # on the global decimated grid
            if b - a < 64 * total:  # too short for the filter's padding: stays missing
                continue
            part = _decimate_stages(signals.data[:, a:b], stages)
            data[:, a // total: a // total + part.shape[1]] = part
    why = f"factor {total}: fs ≥ 2.5 × the {fmax:.4g} Hz band"
    if period:
        why += f", and it divides the input's period: {period} → {period // total} samples"
    meta = {**signals.meta, "decimated": {"factors": stages, "fs_in": signals.fs, "fs_out": fs, "reason": why}}
    return Signals(data=data, fs=fs, channels=signals.channels, units=signals.units, t0=signals.t0, meta=meta)


def decimation_stages(fs: float, fmax: float, *, period: int | None = None) -> list:
    """The stages (factors of at most 10, largest first) :func:`decimate` uses; [] for none.

    Parameters
    ----------
    fs : float
        Sampling frequency in Hz.
    fmax : float
        Highest frequency of interest in Hz; the total factor is at most ``q = floor(fs / (2.5 fmax))``.
    period : int, optional
        Period in samples of a periodic excitation: the total factor is the largest ``d <= q`` that
        divides `period` and factors into stages of at most 10 (none: []). Default None: the stages
        ``min(q, 10)``, then ``q // 10`` and so on (their product at most `q`).

    Returns
    -------
    list of int
        Empty when no total factor of at least 2 fits.

    Raises
    ------
    ValueError
        If `period` is below 2.
    """
    q = int(np.floor(fs / (2.5 * fmax)))
    if period is None:
        stages, left = [], q
        while left >= 2:  # stages of at most 10 (scipy's advice); total factor <= q keeps fs >= 2.5 fmax
            f = min(left, 10)
            stages.append(f)
            left //= f
        return stages
    period = int(period)
    if period < 2:
        raise ValueError(f"{period=} must be at least 2 samples")
    for d in range(min(q, period), 1, -1):
        if period % d:
            continue
        stages, left = [], d
        while left > 1:  # the largest stage <= 10 that divides what is left
            f = next((f for f in range(10, 1, -1) if left % f == 0), None)
            if f is None:  # a prime factor above 10
                break
            stages.append(f)
            left //= f
        if left == 1:
            return stages
    return []


#: order of each decimation stage's anti-alias filter: a Chebyshev type I low-pass of 0.05 dB
#: ripple with its edge at 0.8 of the new Nyquist frequency (scipy.signal.decimate's design), of odd
#: order so that its gain at 0 Hz is exactly 1 (scipy's order 8 passes a mean such as gravity
#: 1.1 % low after the forward-backward pass)
DECIMATION_ORDER = 9


def _decimate_stages(data: np.ndarray, stages: list) -> np.ndarray:
    for f in stages:
        sos = scipy.signal.cheby1(DECIMATION_ORDER, 0.05, 0.8 / f, output="sos")
        data = scipy.signal.sosfiltfilt(sos, data, axis=-1)[..., ::f]
    return data


#: identification methods of ``analyse`` and ``modal`` (:data:`vibroscope.modal.methods.METHOD_CHOICES`)
METHODS = METHOD_CHOICES


@dataclass(frozen=True, kw_only=True)
class IdentifySettings:
    """Settings of one identification pass (see :func:`analyse_signals` for their meaning).

    Attributes
    ----------
    input : str or None
        The force channel; None for output-only identification.
    outputs : tuple of str
        Response channels.
    nperseg : int
        Welch segment length in samples.
    window : str
        Welch window.
    fmin : float or None
        Lower edge (Hz) of the band searched for modes.
    fmax : float
        Upper edge (Hz) of that band.
    n_modes : int or None
        Number of modes for peak picking and FDD (None: every clear peak).
    estimator : {'H1', 'H2', 'Hv'}
        FRF estimator with an input.
    prominence : float
        Smallest peak prominence in dB for FDD/EFDD.
    method : str
        Identification method, one of :data:`vibroscope.modal.methods.METHOD_CHOICES`.
    f_low : float, optional
        Output-only: the lowest resonance (Hz) found in the response, which sets the SSI /
        polyMAX time lags; default None (derived from the band or ``10 fs / nperseg``).
    band : tuple of (float, float), optional
        The band (Hz) the modes are selected in (with an input: the excited band within
        `fmin`, `fmax`); default None (``(fmin, fmax)``).
    select : tuple of float, optional
        Frequencies (Hz) of the modes to take from the stabilization diagram (LSCF, SSI-COV);
        default None (automatic selection).
    period : int, optional
        Period in samples of a periodic input: the FRFs are then period-synchronous; default
        None.
    """

    input: str | None
    outputs: tuple
    nperseg: int
    window: str
    fmin: float | None
    fmax: float
    n_modes: int | None
    estimator: str
    prominence: float
    method: str
    f_low: float | None = None
    band: tuple | None = None
    select: tuple | None = None
    period: int | None = None


def _identify(sig: Signals, s: IdentifySettings):
    """One identification pass at one resolution: (CSD of all channels, FRF or None, Identification)."""
    resolve_method(s.method, has_input=bool(s.input))  # a misfit fails before any spectrum
    G = csd_matrix(sig, nperseg=s.nperseg, window=s.window)
    outputs = list(s.outputs)
    lo, hi = s.band if s.band is not None else (s.fmin, s.fmax)
    h = None
    if s.input:
        h = frf(G, s.input, outputs, estimator=s.estimator)
        if s.period:  # periodic excitation: whole periods, rectangular window, no leakage
            from vibroscope.spectral.periodic import frf_periodic

            h = frf_periodic(sig, s.input, outputs, period=s.period, drop_periods=1)
    f_low = s.f_low or (lo or sig.fs / s.nperseg * 10)  # the lowest resonance sets the lags
    ident = identify(s.method, frf=h, csd=G.select(outputs), signals=None if h is not None else sig.select(outputs),
                     time_series=True, fmin=s.fmin, fmax=s.fmax, band=(lo, hi), n_modes=s.n_modes,
                     prominence=s.prominence, select=s.select, f_low=f_low)
    return G, h, ident


def analyse_signals(
    signals: Signals,
    *,
    input: str | None = None,
    outputs: Sequence[str] | None = None,
    nperseg: int | None = None,
    window: str = "hann",
    fmin: float | None = None,
    fmax: float | None = None,
    n_modes: int | None = None,
    estimator: str = "H1",
    prominence: float = 10.0,
    method: str = "auto",
    select: Sequence[float] | None = None,
    decimation: bool = True,
    on_signals: Callable[[Signals, tuple], None] | None = None,
) -> Analysis:
    """Spectra, FRFs, coherence and modal vectors of a record.

    Without `fmin`/`fmax` the band is chosen from the data: with an input, the band its PSD
    excites (within 20 dB of its maximum, :func:`vibroscope.modal.selection.excited_band`);
    output-only, the lowest resonance up to the frequency below which 95 % of the response
    variance lies (:func:`vibroscope.modal.selection.response_band`). Every method's candidates
    then pass the physical-mode selection of :mod:`vibroscope.modal.selection`; the rejected ones
    are kept in ``Analysis.identification.rejected`` with their reasons.

    Parameters
    ----------
    signals : Signals
        The record (SI units).
    input : str, optional
        The force channel. With it: FRFs from it to every output (`estimator`) and modes by
        LSCF + LSFD (default) or peak picking; without: output-only SSI-COV (default), FDD or EFDD.
    outputs : sequence of str, optional
        Response channels; default every channel but the input.
    nperseg : int, optional
        Welch segment length; default :func:`default_nperseg` (fine enough for the band's lowest
        frequency), then, with an input, doubled while an identified mode's half-power band
        ``2 ζ f_n`` spans fewer than 8 bins and at least 5 averages remain -- with gaps, at least
        5 segments free of missing samples (the damping needs the resolution; a warning says so).
    window : str, optional
        Welch window (default Hann).
    fmin, fmax : float, optional
        Band (Hz) searched for modes; fmax also sets a decimation before the analysis. Default:
        chosen from the data (see above).
    n_modes : int, optional
        Number of modes to report (peak picking and FDD; default every clear peak).
    estimator : {'H1', 'H2', 'Hv'}, optional
        FRF estimator with an input.
    prominence : float, optional
        Smallest prominence (dB) of a peak of the first singular values for FDD/EFDD; default
        10 dB.
    method : str, optional
        One of :data:`vibroscope.modal.methods.METHOD_CHOICES` (the registry
        :data:`~vibroscope.modal.methods.MODAL_METHODS`; each method's result name, such as
        'ssi_cov', is accepted too). 'auto' (default) is LSCF/polyMAX with LSFD with an input (Peeters et al.
        2004) and covariance-driven SSI with clustering of stable poles without (Peeters & De
        Roeck 1999); 'polymax' polyMAX on the output positive power spectra (Peeters & Van der
        Auweraer 2005, the output-only cross-check); 'fdd' / 'efdd' frequency-domain decomposition (Brincker et al. 2001) with
        half-power / enhanced damping; 'peak' peak picking on the FRFs. With an input, 'polymax'
        is LSCF (polyMAX is the poly-reference LSCF).
    select : sequence of float, optional
        LSCF and SSI-COV: take the modes at these frequencies (Hz) from the stabilization diagram
        instead of the automatic physical-mode selection.
    decimation : bool, optional
        Decimate to the band (:func:`decimate`) when ``fmax < 0.4 fs`` (default True); False
        analyses the record at its own rate.
    on_signals : callable, optional
        Called once as ``on_signals(signals, outputs)`` with the record the modes are identified
        from (faults applied, decimated: ``Analysis.signals``) and the response channels, before
        the identification: outputs that need only the time series start from them while the
        modes are computed (:class:`vibroscope.viewers.ahead.TimeSeriesAhead`).

    Returns
    -------
    Analysis

    Raises
    ------
    KeyError
        If `input` or an output is not a channel of `signals`.
    ValueError
        If the record is too short for the segment length, the method does not fit the
        presence or absence of an input, ``fmin > fmax``, `fmax` is above the Nyquist
        frequency ``fs / 2``, or a signal fault stops the analysis
        (an all-missing channel, a zero or constant input, a record shorter than `nperseg`); the
        message names the channel or option and the remedy.

    Notes
    -----
    Signal faults (:mod:`vibroscope.faults`) are detected first and handled as documented there:
    missing samples (NaN) skip the Welch segments they touch; Inf, clipped and dropped-out samples
    are set to NaN (masked, never replaced by other numbers) and skipped the same way; constant
    outputs are left out; each fault is a line of ``Analysis.warnings`` and is listed in
    ``Analysis.faults``; expected properties (gravity on an accelerometer axis, a constant output)
    are listed in ``Analysis.notes`` instead, with no warning. A sample missing in one analysed channel is treated as missing in all
    of them, so that every entry of the spectral matrix, the FRFs, the coherence and the SSI
    covariances comes from the same segments (or lag windows) -- unless that would leave less
    than half of the record, when each pair keeps its own segments (a note says so); the
    automatic `nperseg` is halved until at least 8 segments of every channel fit between the
    gaps, and a note says how many segments were averaged. Decimation never filters across a gap (:func:`decimate`).

    Decimation keeps the rate at least 2.5 `fmax` (the band's top when `fmax` is not given). With
    an input, its period is looked for first at the full rate (:func:`vibroscope.spectral.periodic.detect_period`,
    low-passed to `fmax`); a periodic input is decimated only by a factor that divides its period,
    or not at all. ``settings["decimation"]`` says what was done and why: ``fs_in``, ``fs_out``
    (Hz), ``factors`` (the stages, [] when not decimated) and ``reason`` (None when decimating
    would not gain).

    An input in an acceleration unit (m/s², g) gets a note: its FRFs are transmissibilities.
    """
    _check_arguments(signals, input=input, fmin=fmin, fmax=fmax, method=method, select=select)
    notes = list(signals.meta.get("warnings", []))
    outputs = _select_outputs(signals, input, outputs, notes)
    sig, outputs, faults, expected = _handle_faults(signals, input, outputs, nperseg, notes)
    sig, gappy = _common_gaps(sig, notes)
    undecimated = sig
    plan, sig = _plan(sig, input=input, outputs=outputs, nperseg=nperseg, window=window, fmin=fmin, fmax=fmax,
                      estimator=estimator, method=method, decimation=decimation, gappy=gappy, notes=notes)
    if on_signals is not None:
        on_signals(sig, tuple(plan.outputs))
    return _execute(plan, sig, undecimated, auto_nperseg=nperseg is None, gappy=gappy, n_modes=n_modes,
                    prominence=prominence, method=method, select=select, notes=notes, faults=faults,
                    expected=expected)


def _check_arguments(signals: Signals, *, input, fmin, fmax, method, select) -> None:
    """The options' own errors, before any look at the data."""
    from vibroscope._checks import check_option

    check_option("method", method, METHODS)
    if select is not None and not resolve_method(method, has_input=input is not None).selects:
        raise ValueError(f"select= picks poles from a stabilization diagram: method "
                         f"{' or '.join(repr(m.key) for m in MODAL_METHODS.values() if m.selects)}, not {method!r}")
    if fmin is not None and fmax is not None and fmin > fmax:
        raise ValueError(f"{fmin=} Hz must not exceed {fmax=} Hz: swap them")
    if fmax is not None and fmax > signals.fs / 2:
        raise ValueError(f"fmax={fmax:g} Hz is above the Nyquist frequency {signals.fs / 2:g} Hz (fs={signals.fs:g} "
                         f"Hz): nothing above fs/2 is measured")


def _select_outputs(signals: Signals, input, outputs, notes: list) -> list:
    """The response channels (default every channel but the input), each checked to be in `signals`;
    an input in an acceleration unit gets its note (transmissibilities)."""
    outputs = [c for c in signals.channels if c != input] if outputs is None else list(outputs)
    if input is not None:
        unit = signals.units[signals.index(input)]
        if unit in _ACCELERATION_UNITS:  # base excitation: response over input acceleration
            notes.append(f"input {input} is an acceleration ({unit}), not a force: the FRFs are transmissibilities "
                         f"(response / input acceleration), not FRFs, and their modes are those of the structure "
                         f"held at the input point")
    for c in outputs:
        signals.index(c)
    return outputs


def _handle_faults(signals: Signals, input, outputs: list, nperseg, notes: list):
    """Signal faults detected on the data and their documented actions applied (masking as NaN,
    dropping constant outputs), or a ValueError naming the channel and the remedy:
    (the input and the responses left, the responses left, faults, notes)."""
    chans = ([input] if input else []) + outputs
    sig = signals.select(chans)
    present = np.isfinite(sig.data)
    n_valid = int(present.all(axis=0).sum())
    # the automatic nperseg is halved to fit between gaps (_nperseg_for): only a stretch shorter than
    # what it can reach stops the analysis
    nper_check = nperseg or _auto_nperseg(sig, n=max(n_valid, 1))
    found = detect_faults(sig, input=input, nperseg=nper_check)
    faults = tuple(f for f in found if not f.note)
    expected = tuple(f for f in found if f.note)  # gravity, constant outputs: notes, not warnings
    flat = [f.channel for f in found if f.action == "drop"]
    if flat:  # e.g. the unused axes of a one-axis IMU: no information, singular spectra
        outputs = [c for c in outputs if c not in flat]
    if not outputs:
        raise ValueError("no non-constant response channel to analyse")
    notes += [str(f) for f in faults]
    return apply_faults(sig, found), outputs, faults, expected


def _common_gaps(sig: Signals, notes: list) -> tuple[Signals, bool]:
    """(the record, whether it has gaps): a sample missing in one channel made missing in all, so
    that every spectral entry and covariance comes from the same segments (consistent H1/H2/Hv,
    coherence and SSI covariances) -- unless that leaves less than half the record: then each pair
    keeps its own segments."""
    present = np.isfinite(sig.data).all(axis=0)
    gappy = not present.all()
    if gappy:
        n_valid = int(present.sum())
        starts, stops = true_runs(present)
        longest = int((stops - starts).max(initial=0))
        if n_valid >= sig.n_samples // 2:
            data = np.array(sig.data)
            data[:, ~present] = np.nan
            sig = Signals(data=data, fs=sig.fs, channels=sig.channels, units=sig.units, t0=sig.t0, meta=sig.meta)
            notes.append(f"{sig.n_samples - n_valid} of {sig.n_samples} samples missing in at least one "
                         f"channel (longest stretch without a gap: {longest} samples, {longest / sig.fs:.4g} s); "
                         f"they are missing in every channel for the analysis")
        else:
            notes.append(f"{sig.n_samples - n_valid} of {sig.n_samples} samples missing in at least one "
                         f"channel: too many to drop them from every channel; each channel pair is averaged "
                         f"over its own segments (estimates from different segment sets)")
    return sig, gappy


def _plan(sig: Signals, *, input, outputs, nperseg, window, fmin, fmax, estimator, method, decimation, gappy,
          notes) -> tuple[AnalysisPlan, Signals]:
    """The plan of the analysis from the prepared record, and the record at the planned rate:
    the band, the input's period, the decimation, the band the modes are selected in at the
    analysed rate, the segment length and the method."""
    f_low, fmax = _band_from_data(sig, input, outputs, fmin, fmax, notes)
    fs_in = sig.fs
    # a periodic input is looked for at the full rate (low-passed to the band when a decimation
    # would gain): the decimation factor must divide its period (whole periods for the FRFs)
    wanted = bool(fmax is not None and fmax < 0.4 * sig.fs and decimation_stages(sig.fs, fmax))
    per = _input_period(sig, input, fmax if wanted else None, gappy, notes)
    sig, factors, reason = _decimate_to_band(sig, fmax, per, wanted=wanted, decimation=decimation, gappy=gappy,
                                             notes=notes)
    fmax_eff = fmax if fmax is not None else 0.4 * sig.fs
    if input:  # the excited band again at the analysed rate
        fw, P = _quick_welch(sig[input][None], sig.fs, _auto_nperseg(sig))
        lo_x, hi_x = excited_band(fw, P[0])
        band = (max(fmin or 0.0, lo_x), min(fmax_eff, hi_x))
    else:
        band = (fmin, fmax_eff)
    period = None
    if per is not None:
        q = int(round(fs_in / sig.fs))
        period = per.period_samples // q
        rate = f" at {sig.fs:g} Hz; {per.period_samples} at {fs_in:g} Hz" if q > 1 else ""
        notes.append(f"periodic input: period {per.period_s:.6g} s ({period} samples{rate}, "
                     f"{per.n_periods} periods, score {per.score:.4f}); FRFs period-synchronous "
                     f"(rectangular window over whole periods, the first period dropped)")
    if nperseg is None:
        nperseg = _auto_nperseg(sig, fmin=fmin or (f_low / 6 if f_low else None))
    plan = AnalysisPlan(input=input, outputs=tuple(outputs), fs_in=fs_in, fs=sig.fs, factors=tuple(factors),
                        decimation_reason=reason, fmin=fmin, fmax=fmax_eff, band=tuple(band), f_low=f_low,
                        period=period, nperseg=nperseg, window=window,
                        estimator=estimator if input else None,
                        method=resolve_method(method, has_input=bool(input)).name)
    return plan, sig


def _band_from_data(sig: Signals, input, outputs, fmin, fmax, notes: list) -> tuple[float | None, float | None]:
    """(the lowest resonance output-only or None, the band's top): without `fmax` (and always
    output-only, for the lowest resonance) from a quick Welch pass at ~16 averages: with an input its
    excited band, without the responses' band (:mod:`vibroscope.modal.selection`)."""
    f_low, band_note = None, None
    if fmax is None or not input:
        n0 = _auto_nperseg(sig)
        fw, P = _quick_welch(sig.data, sig.fs, n0)
        if input:
            lo_x, hi_x = excited_band(fw, P[0])
            fmax = hi_x if fmax is None else fmax
            band_note = f"band from the input: {lo_x:.4g}–{hi_x:.4g} Hz (its PSD within 20 dB of the maximum)"
        else:
            f_low, hi_r = response_band(fw, P[[sig.channels.index(c) for c in outputs]], fmin=fmin)
            if fmax is None:
                fmax = hi_r
                band_note = (f"band from the response: lowest resonance {f_low:.4g} Hz, 95 % of the variance "
                             f"below {hi_r:.4g} Hz")
        if band_note:
            notes.append(band_note + " (set --fmin/--fmax to choose)")
    return f_low, fmax


def _input_period(sig: Signals, input, fmax, gappy: bool, notes: list):
    """The input's period (:func:`vibroscope.spectral.periodic.detect_period`, low-passed to `fmax`
    when given) when it is periodic over at least 3 periods, else None; not looked for in a
    record with gaps."""
    if input and gappy:
        notes.append("periodic input not looked for: the record has gaps")
        return None
    if not input:
        return None
    from vibroscope.spectral.periodic import detect_period

    per = detect_period(sig[input], sig.fs, fmax=fmax)
    return per if per.is_periodic and per.n_periods >= 3 else None


def _decimate_to_band(sig: Signals, fmax, per, *, wanted: bool, decimation: bool, gappy: bool, notes: list):
    """(the record at the analysed rate, the decimation's stage factors, the reason or None): a
    periodic input only by a factor that divides its period, a record with gaps only when enough
    segments survive the filter's settling."""
    if wanted and not decimation:
        return sig, [], "decimation turned off"
    if not wanted:
        return sig, [], None
    dec = decimate(sig, fmax, period=per.period_samples if per else None)
    if dec is sig:  # a periodic input whose period no allowed factor divides
        return sig, [], (f"no factor up to {int(sig.fs // (2.5 * fmax))} divides the input's period of "
                         f"{per.period_samples} samples: a periodic excitation needs whole periods")
    if not gappy or _clean_segments(dec, 16) >= 8:
        return dec, list(dec.meta["decimated"]["factors"]), dec.meta["decimated"]["reason"]
    # the decimation filter's settling eats short stretches between gaps
    notes.append(f"not decimated to the {fmax:.4g} Hz band: the stretches between gaps are too short "
                 f"for the decimation filter to settle")
    return sig, [], "the stretches between gaps are too short for the decimation filter"


def _execute(plan: AnalysisPlan, sig: Signals, undecimated: Signals, *, auto_nperseg: bool, gappy: bool, n_modes,
             prominence, method, select, notes: list, faults, expected) -> Analysis:
    """The straight pass of a plan: identification (the automatic segment refined for the damping,
    :func:`_identify_refined`, recorded in the plan as ``nperseg_refined``), the spectra, the
    severity of the record before any decimation."""
    from vibroscope import modal

    s = IdentifySettings(input=plan.input, outputs=plan.outputs, nperseg=plan.nperseg, window=plan.window,
                         fmin=plan.fmin, fmax=plan.fmax, n_modes=n_modes, estimator=plan.estimator,
                         prominence=prominence, method=method, f_low=plan.f_low, band=plan.band,
                         select=None if select is None else tuple(select), period=plan.period)
    G, h, ident, nperseg = _identify_refined(sig, s, auto=auto_nperseg, gappy=gappy, notes=notes)
    if nperseg != plan.nperseg:  # the damping refinement, recorded in the plan the report prints
        plan = replace(plan, nperseg_refined=nperseg)
    mm = ident.modes
    psd = G.psd()
    Gout = G.select(list(plan.outputs))
    sv = modal.singular_values(Gout)
    if "n_segments" in G.settings:
        k = G.settings["n_averages"]
        few = (f": few averages, the spectra have a high variance (about {100 / np.sqrt(k):.0f} %)"
               if k < MIN_AVERAGES else "")
        notes.append(f"{k} of {G.settings['n_segments']} Welch segments averaged (nperseg={nperseg}); "
                     f"those touching a missing sample were skipped{few}")
    severity = _severity(undecimated.select(list(plan.outputs)), notes)
    settings = dict(G.settings, fmin=plan.fmin, fmax=plan.fmax, estimator=plan.estimator, input=plan.input,
                    outputs=list(plan.outputs), method=mm.method, band_hz=list(plan.band),
                    decimation=plan.decimation_dict())
    return Analysis(signals=sig, psd=psd, csd=Gout, frf=h, modal=mm, singular_values=sv, settings=settings,
                    warnings=notes, identification=ident, severity=severity, faults=faults, notes=expected, plan=plan)


def _identify_refined(sig: Signals, s: IdentifySettings, *, auto: bool, gappy: bool, notes: list):
    """(CSD of all channels, FRF or None, Identification, final nperseg): with an input and the
    automatic segment, the resolution is refined (nperseg doubled) while an identified mode's
    half-power band spans fewer than 8 bins and >= 5 averages remain (with gaps: >= 5 segments free
    of missing samples). Half-power bands should span several bins for the damping to be resolved
    (Brandt 2011, §14.3); FRFs only: output-only FDD loses more to the fewer averages than it gains
    in resolution."""
    refinements = []
    nperseg = s.nperseg
    while True:
        with warnings.catch_warnings():  # said once below, as a note
            warnings.simplefilter("ignore", FewAveragesWarning)
            G, h, ident = _identify(sig, replace(s, nperseg=nperseg))
        mm = ident.modes
        bw = 2 * np.asarray(mm.damping_ratios) * np.asarray(mm.natural_frequencies)
        df = sig.fs / nperseg
        if (not auto or not s.input or s.period or not np.any(np.isfinite(bw) & (bw < 8 * df))
                or 2 * nperseg > 2 * sig.n_samples / 6 or (gappy and _clean_segments(sig, 2 * nperseg) < 5)):
            break
        refinements.append(nperseg)
        nperseg *= 2
    if refinements:
        notes.append(f"resolution refined for the damping: nperseg {refinements[0]} -> {nperseg} "
                     f"(df {sig.fs / refinements[0]:.4g} -> {sig.fs / nperseg:.4g} Hz)")
    return G, h, ident, nperseg


#: units of an acceleration channel (an input in one of them makes a transmissibility)
_ACCELERATION_UNITS = ("m/s^2", "m/s²", "m s^-2", "g")


def _auto_nperseg(sig: Signals, *, n: int | None = None, fmin: float | None = None) -> int:
    """The automatic segment length, one rule for every look at the data (the fault check, the
    quick band passes, the plan): :func:`default_nperseg` of `n` samples (default the record's)
    at the record's rate (lengthened for `fmin`), halved to fit between gaps (:func:`_nperseg_for`)."""
    return _nperseg_for(sig, default_nperseg(sig.n_samples if n is None else n, sig.fs, fmin=fmin))


def _nperseg_for(sig: Signals, nperseg: int) -> int:
    """`nperseg`, halved (a power of two, at least 16) until at least 8 Welch segments (50 %
    overlap, on the record's grid) of every channel hold no missing sample; unchanged for a
    gap-free record."""
    if np.isfinite(sig.data).all():
        return nperseg
    n = int(nperseg)
    while n > 16 and _clean_segments(sig, n) < 8:
        n //= 2
    return n


def _clean_segments(sig: Signals, n: int) -> int:
    """Fewest Welch segments of `n` samples (50 % overlap) free of missing samples, over the channels."""
    missing = ~np.isfinite(sig.data)
    if sig.n_samples < n:
        return 0
    cm = np.concatenate((np.zeros((missing.shape[0], 1), np.int64), np.cumsum(missing, axis=1)), axis=1)
    starts = np.arange(0, sig.n_samples - n + 1, n - n // 2)
    return int(np.count_nonzero(cm[:, starts + n] == cm[:, starts], axis=1).min())


def _quick_welch(data: np.ndarray, fs: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD that skips segments touching missing samples (quiet about few averages)."""
    from vibroscope.spectral import welch

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sp = welch(data, fs, nperseg=nperseg)
    return sp.frequencies, sp.values


def _severity(sig: Signals, notes: list):
    """ISO 20816 velocity RMS (10–1000 Hz, mm/s) of the acceleration channels, or None."""
    from vibroscope.spectral.integration import vibration_severity

    acc = [c for c, u in zip(sig.channels, sig.units) if u in _ACCELERATION_UNITS]
    if not acc or sig.fs / 2 <= 10.0:
        return None
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", FewAveragesWarning)
            sev = vibration_severity(sig.select(acc))
        for w in caught:
            if issubclass(w.category, FewAveragesWarning):
                notes.append(f"vibration severity: {w.message}")
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        return sev
    except ValueError as exc:
        notes.append(f"vibration severity not computed: {exc}")
        return None


def summary_dict(analysis: Analysis, *, source: str | None = None, true_modes: Any = None) -> dict:
    """The machine-readable summary (the ``--json`` file of ``vibroscope analyse``).

    Keys: ``fs`` (Hz), ``channels``, ``warnings``, ``faults`` (one dict per signal fault:
    ``channel``, ``kind``, ``message``, ``action``, ``n_samples``, ``n_spans``, ``spans`` (sample
    index ranges), ``times_s`` (s from the first sample); see :meth:`vibroscope.faults.Fault.to_dict`), ``notes``
    (expected properties, e.g. gravity on an accelerometer axis, in the same form), ``modes`` (each ``frequency_hz``,
    ``damping_ratio``, ``frequency_std_hz``, ``damping_std``, ``shape`` {path: [re, im]}, ``mpc``,
    ``mpd``, ``stable``), ``rejected_modes`` (``frequency_hz``, ``damping_ratio``, ``reason``), plus ``input``, ``outputs``,
    ``settings``, ``plan`` (:meth:`AnalysisPlan.to_dict`), ``timebase``, ``input_choice`` (the line naming the
    force-like channel taken as the input, or why none was, when the log was searched for one) and,
    with `true_modes`, ``true_modes``. A streamed analysis (``settings["streamed"]``) holds no time
    series: no ``faults``, ``notes``, ``plan``, ``vibration_severity``, ``identification`` or record
    meta keys.

    Parameters
    ----------
    analysis : Analysis
        The result of :func:`analyse_signals` or :func:`vibroscope.stream.analyse_stream`.
    source : str, optional
        Where the record came from (e.g. the log's path), stored under ``source``.
    true_modes : Modes, optional
        Known modes (``natural_frequencies`` in Hz, ``damping_ratios``) to list beside the
        identified ones, e.g. :meth:`vibroscope.models.LumpedModel.modes`.

    Returns
    -------
    dict
        JSON-serialisable.
    """
    from vibroscope.modal.automatic import modes_document

    ident = analysis.identification
    doc = modes_document(analysis.modal, ident.rejected if ident is not None else ())
    whole = not analysis.streamed  # faults, severity and the record's meta need the time series
    out = {
        "source": source,
        "fs": analysis.fs,
        "n_samples": analysis.n_samples,
        "duration_s": analysis.duration_s,
        "channels": list(analysis.channels),
        "units": dict(zip(analysis.channels, analysis.units)),
        "input": analysis.settings.get("input"),
        "outputs": analysis.settings.get("outputs"),
        "warnings": list(analysis.warnings),
    }
    if whole:
        out["faults"] = [f.to_dict() for f in analysis.faults]
        out["notes"] = [f.to_dict() for f in analysis.notes]
    out.update(modal_method=analysis.modal.method, modes=doc["modes"], rejected_modes=doc["rejected"])
    if not whole and analysis.input_choice:
        out["input_choice"] = analysis.input_choice
    out["settings"] = {k: v for k, v in analysis.settings.items() if k not in ("outputs", "input_choice")}
    if analysis.plan is not None:
        out["plan"] = analysis.plan.to_dict()
    sev = analysis.severity
    if sev is not None:
        out["vibration_severity"] = {"standard": "ISO 20816-1 (velocity RMS)", "band_hz": list(sev.band_hz),
                                     "velocity_rms_mm_s": dict(zip(sev.channels, sev.velocity_rms_mm_s.tolist())),
                                     "note": sev.note}
    if ident is not None and whole:
        out["identification"] = {k: v for k, v in ident.settings.items() if k not in ("orders",)}
    meta = analysis.signals.meta if whole else {}
    for key in ("timebase", "skipped", "decimated", "resampled", "input_choice"):
        if key in meta:
            out[key] = meta[key]
    if true_modes is not None:
        out["true_modes"] = [
            {"frequency_hz": float(f), "damping_ratio": float(z)}
            for f, z in zip(true_modes.natural_frequencies, true_modes.damping_ratios)
        ]
    return jsonable(out)
