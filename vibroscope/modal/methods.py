"""The modal identification methods, declared once.

:data:`MODAL_METHODS` is the one registry of the methods: what each needs (an input, i.e. FRFs;
the time series, or the spectra suffice), its runner, the names it is asked for by and its display
name. Everything else reads it: :func:`vibroscope.pipeline.analyse_signals`,
:func:`vibroscope.stream.analyse_stream`, ``vibroscope analyse`` and ``vibroscope modal``
(``--method`` choices and help, the report), the stabilization-diagram figure.
:func:`identify` is the one dispatch, :func:`resolve_method` the one check of a method against
the data at hand (one error per misfit, one for an unknown name).

``'auto'`` is no method but a rule: LSCF with an input; without one SSI-COV on the time series,
EFDD on spectra alone. ``'polymax'`` names polyMAX on the output spectra without an input and
LSCF (polyMAX is the poly-reference LSCF) on FRFs.

Adding a method: one new module whose ``run(call: MethodCall) -> Identification`` calls the
estimator and the physical-mode selection, and one :class:`ModalMethod` entry here (see
CONTRIBUTING.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from vibroscope._checks import check_option
from vibroscope.modal.automatic import Identification, auto_lscf, auto_ssi, line_spacing, polymax_oma
from vibroscope.modal.fdd import fdd
from vibroscope.modal.peak_picking import peak_picking
from vibroscope.modal.selection import select_modes

__all__ = ["ModalMethod", "MethodCall", "MODAL_METHODS", "METHOD_CHOICES", "AUTO", "lookup_method", "resolve_method",
           "identify", "display_name", "uses_input"]

#: the rule that picks a method from the data (see the module notes)
AUTO = "auto"


@dataclass(frozen=True, kw_only=True)
class MethodCall:
    """What a runner gets: the data of one identification and its settings.

    Attributes
    ----------
    frf : FRF or None
        ``H[f, output, input]`` (the input-output methods).
    csd : CrossSpectralMatrix or None
        Cross-spectral matrix of the responses (FDD, EFDD).
    signals : Signals or None
        The responses' time series (SSI-COV, polyMAX on the output spectra); None when only the
        spectra are at hand (a streamed analysis).
    fmin, fmax : float or None
        Band (Hz) the estimator searches (peak picking, FDD, the lower edge of SSI-COV).
    band : tuple of (float, float), optional
        Band (Hz) the modes are selected in; default None (``(fmin, fmax)``).
    n_modes : int or None
        Number of modes for peak picking and FDD (None: every clear peak).
    prominence : float
        Smallest peak prominence in dB for FDD/EFDD.
    select : tuple of float or None
        Frequencies (Hz) of the modes to take from the stabilization diagram (LSCF, SSI-COV).
    f_low : float or None
        The lowest resonance (Hz), which sets the time lags of SSI-COV and polyMAX.
    merge_duplicates : bool
        Peak picking, FDD: candidates within two lines of the frequency axis and alike in shape
        are one mode (``resolution_hz`` of :func:`~vibroscope.modal.selection.select_modes`).
    """

    frf: Any = None
    csd: Any = None
    signals: Any = None
    fmin: float | None = None
    fmax: float | None = None
    band: tuple | None = None
    n_modes: int | None = None
    prominence: float = 10.0
    select: tuple | None = None
    f_low: float | None = None
    merge_duplicates: bool = True

    @property
    def selection_band(self) -> tuple:
        """``band``, or ``(fmin, fmax)`` when it is None."""
        return self.band if self.band is not None else (self.fmin, self.fmax)


@dataclass(frozen=True, kw_only=True)
class ModalMethod:
    """One modal identification method of the registry.

    Attributes
    ----------
    name : str
        The name results carry (``ModalModel.method``, ``settings["method"]``).
    key : str
        The short name asked for (``--method``, ``method=``); `name` is accepted too.
    display : str
        How reports and figures name it.
    needs_input : bool
        True: runs on FRFs (an input channel); False: output-only.
    needs_time_series : bool
        True: needs the responses' time series (a streamed analysis holds spectra only).
    selects : bool
        Takes ``select=`` frequencies from a stabilization diagram.
    order : str or None
        What the stabilization diagram's model order counts; None without a diagram.
    runner : callable
        ``runner(call: MethodCall) -> Identification``.
    with_input : str or None
        The method (`name`) that this one's names mean when an input is given (polyMAX on FRFs is
        LSCF); None: an input is refused.
    no_damping_note : str
        Why a damping ratio it gives reads "-" in the report (``"   (zeta -: <note>)"``); default
        ``"not estimated"``.
    cross_check : bool
        ``vibroscope modal`` runs polyMAX on the output spectra beside it and prints the pairing
        (:func:`vibroscope.commands.modal.cross_check_text`); default False.
    """

    name: str
    key: str
    display: str
    needs_input: bool
    needs_time_series: bool
    selects: bool
    order: str | None
    runner: Callable[[MethodCall], Identification]
    with_input: str | None = None
    no_damping_note: str = "not estimated"
    cross_check: bool = False


def _selected(mm, call: MethodCall, lo, hi, axis, coherence=None) -> Identification:
    """The physical modes among `mm`'s candidates in ``[lo, hi]`` Hz."""
    res = line_spacing(axis) if call.merge_duplicates else None
    sel = select_modes(mm, fmin=lo, fmax=hi, coherence=coherence, resolution_hz=res)
    return Identification(sel.modes, sel.rejected, None, {"method": mm.method, **sel.criteria})


def _run_lscf(call: MethodCall) -> Identification:
    lo, hi = call.selection_band
    return auto_lscf(call.frf, fmin=lo, fmax=hi, select=call.select)


def _run_peak(call: MethodCall) -> Identification:
    h = call.frf
    mm = peak_picking(h, n_modes=call.n_modes, fmin=call.fmin, fmax=call.fmax)
    coh = (h.frequencies, h.coherence) if np.any(np.isfinite(h.coherence)) else None
    return _selected(mm, call, *call.selection_band, h.frequencies, coh)


def _run_ssi(call: MethodCall) -> Identification:
    return auto_ssi(call.signals, f_low=call.f_low, fmin=call.fmin, fmax=call.selection_band[1], select=call.select)


def _run_polymax(call: MethodCall) -> Identification:
    return polymax_oma(call.signals, f_low=call.f_low, fmin=call.fmin, fmax=call.selection_band[1])


def _fdd(call: MethodCall, efdd: bool) -> Identification:
    G = call.csd
    # two singular values: close modes (e.g. a tower's two bending directions) both show
    mm = fdd(G, n_modes=call.n_modes, fmin=call.fmin, fmax=call.fmax, n_singular=min(2, len(G.channels)),
             prominence=call.prominence, efdd=efdd)
    return _selected(mm, call, call.fmin, call.selection_band[1], G.frequencies)


def _run_fdd(call: MethodCall) -> Identification:
    return _fdd(call, efdd=False)


def _run_efdd(call: MethodCall) -> Identification:
    return _fdd(call, efdd=True)


#: the registry: every modal identification method, by the name results carry
MODAL_METHODS: dict[str, ModalMethod] = {m.name: m for m in (
    ModalMethod(name="lscf", key="lscf", display="LSCF/polyMAX + LSFD", needs_input=True, needs_time_series=False,
                selects=True, order="polynomial order", runner=_run_lscf),
    ModalMethod(name="ssi_cov", key="ssi", display="SSI-COV", needs_input=False, needs_time_series=True,
                selects=True, order="block rows", runner=_run_ssi, cross_check=True),
    ModalMethod(name="polymax_oma", key="polymax", display="polyMAX on the output spectra", needs_input=False,
                needs_time_series=True, selects=False, order="polynomial order", runner=_run_polymax,
                with_input="lscf"),
    ModalMethod(name="fdd", key="fdd", display="FDD", needs_input=False, needs_time_series=False, selects=False,
                order=None, runner=_run_fdd, no_damping_note="FDD gives no damping; --method efdd estimates it"),
    ModalMethod(name="efdd", key="efdd", display="EFDD", needs_input=False, needs_time_series=False,
                selects=False, order=None, runner=_run_efdd,
                no_damping_note="not estimated; EFDD found no decaying correlation in the peak's bell, the frequency "
                                "is the peak's"),
    ModalMethod(name="peak_picking", key="peak", display="peak picking", needs_input=True, needs_time_series=False,
                selects=False, order=None, runner=_run_peak),
)}

_BY_NAME = {n: m for m in MODAL_METHODS.values() for n in dict.fromkeys((m.key, m.name))}

#: every value ``method=`` and ``--method`` accept: 'auto', then each method's key and name
METHOD_CHOICES = (AUTO, *_BY_NAME)


def lookup_method(method: str) -> ModalMethod | None:
    """The registry's entry that `method` names, whatever the data (None for ``'auto'``).

    Parameters
    ----------
    method : str
        One of :data:`METHOD_CHOICES`: a method's `key` or `name`, or ``'auto'``.

    Returns
    -------
    ModalMethod or None

    Raises
    ------
    ValueError
        ``"Invalid value for the 'method' parameter. Allowed values are ..., but got ... instead."``
        (the one error of an unknown method).

    Examples
    --------
    >>> lookup_method("ssi").name
    'ssi_cov'
    """
    check_option("method", method, METHOD_CHOICES)
    return _BY_NAME.get(method)


def uses_input(method: str) -> bool:
    """Whether `method` runs on FRFs when an input channel is at hand.

    Parameters
    ----------
    method : str
        One of :data:`METHOD_CHOICES`.

    Returns
    -------
    bool
        True for ``'auto'``, the input-output methods and those with a `with_input` method.

    Raises
    ------
    ValueError
        If `method` is not one of :data:`METHOD_CHOICES`.
    """
    m = lookup_method(method)
    return m is None or m.needs_input or m.with_input is not None


def _keys(ok: Callable[[ModalMethod], bool]) -> str:
    return ", ".join(repr(m.key) for m in MODAL_METHODS.values() if ok(m))


def resolve_method(method: str, *, has_input: bool, time_series: bool = True) -> ModalMethod:
    """The registry's method that `method` names for the data at hand, or the one error of a misfit.

    Parameters
    ----------
    method : str
        One of :data:`METHOD_CHOICES`.
    has_input : bool
        An input channel (FRFs) is at hand.
    time_series : bool, optional
        The responses' time series are at hand (False: spectra only); default True.

    Returns
    -------
    ModalMethod
        ``'auto'``: LSCF with an input, else SSI-COV with the time series, else EFDD.

    Raises
    ------
    ValueError
        ``"Invalid value for the 'method' parameter. Allowed values are ..."`` for a name not in
        :data:`METHOD_CHOICES`; ``"method='fdd' (FDD) is output-only; with an input use 'lscf',
        'peak'"``, ``"method='lscf' (...) needs an input (force) channel; output-only use ..."``,
        ``"method='ssi' (SSI-COV) needs the time series; spectra alone: use ..."`` when it does
        not fit the data.
    """
    m = lookup_method(method)
    if m is None:
        m = MODAL_METHODS["lscf" if has_input else "ssi_cov" if time_series else "efdd"]
    elif has_input and not m.needs_input:
        if m.with_input is None:
            raise ValueError(f"method={method!r} ({m.display}) is output-only; with an input use "
                             f"{_keys(lambda k: k.needs_input)}")
        m = MODAL_METHODS[m.with_input]
    elif not has_input and m.needs_input:
        raise ValueError(f"method={method!r} ({m.display}) needs an input (force) channel; output-only use "
                         f"{_keys(lambda k: not k.needs_input and (time_series or not k.needs_time_series))}")
    if m.needs_time_series and not time_series:
        raise ValueError(f"method={method!r} ({m.display}) needs the time series; a streamed analysis has the "
                         f"spectra only: use {_keys(lambda k: not k.needs_input and not k.needs_time_series)} "
                         f"(or {AUTO!r})")
    return m


def identify(method: str, *, frf=None, csd=None, signals=None, time_series: bool | None = None,
             **settings) -> Identification:
    """Modes by the registry's method for `method` (the one dispatch of the analysers).

    Parameters
    ----------
    method : str
        One of :data:`METHOD_CHOICES`; resolved by :func:`resolve_method` (an input is at hand
        when `frf` is given).
    frf : FRF, optional
        Input-output FRFs.
    csd : CrossSpectralMatrix, optional
        Cross-spectral matrix of the responses.
    signals : Signals, optional
        The responses' time series.
    time_series : bool, optional
        Whether time series are at hand; default whether `signals` is given.
    **settings
        The other fields of :class:`MethodCall` (``fmin``, ``fmax``, ``band``, ``n_modes``,
        ``prominence``, ``select``, ``f_low``, ``merge_duplicates``).

    Returns
    -------
    Identification
        Modes, rejected candidates, stabilization diagram and settings; ``settings["method"]``
        and ``modes.method`` are the method's `name`.

    Raises
    ------
    ValueError
        For an unknown method or one that does not fit the data (:func:`resolve_method`), or
        from the method itself.
    """
    ts = signals is not None if time_series is None else time_series
    m = resolve_method(method, has_input=frf is not None, time_series=ts)
    return m.runner(MethodCall(frf=frf, csd=csd, signals=signals, **settings))


def display_name(name: str) -> str:
    """How reports name the method a result carries (`name` itself when it is not registered).

    Parameters
    ----------
    name : str
        ``ModalModel.method`` (``'ssi_cov'``, ``'lscf'``, ...) or a key (``'ssi'``).

    Returns
    -------
    str
        E.g. ``'SSI-COV'``.
    """
    m = _BY_NAME.get(name)
    return m.display if m is not None else name
