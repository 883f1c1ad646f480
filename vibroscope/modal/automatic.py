"""Identification without hand-set bands or orders: the defaults of ``vibroscope analyse`` and
``vibroscope modal``.

- Output-only (:func:`auto_ssi`): SSI-COV with covariance lags covering two periods of the
  record's lowest resonance, reference channels chosen by pivoted QR of the correlation matrix
  (the most linearly independent sensors; Peeters & De Roeck 1999 use references to cut the
  cost), orders up to 120, clustering of stable poles, physical-mode selection
  (:mod:`vibroscope.modal.selection`) and block-bootstrap uncertainties
  (:mod:`vibroscope.modal.uncertainty`).
- With an input (:func:`auto_lscf`): LSCF/polyMAX over the excited band, clustering of stable
  poles, physical-mode selection (excited band, coherence, and one mode for candidates within two
  lines of the FRF with the same shape: a lightly damped mode that a coarse resolution splits),
  LSFD residues with lower and upper residuals, and the synthesized FRFs.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from vibroscope.modal._results import ModalModel
from vibroscope.modal.selection import DAMPING_RANGE, MIN_MPC, RejectedMode, cluster_poles, select_modes
from vibroscope.signals import Signals


def one_blas_thread(fn):
    """Decorator: run `fn` with every BLAS thread pool limited to one thread (threadpoolctl).

    Modal identification is many small and medium dense factorisations (SVDs, QRs, least
    squares): on this project's 2-core machine a BLAS pool of two threads per library (numpy's
    and scipy's OpenBLAS each start their own) gains nothing when the machine is idle and,
    when it is loaded, spins against the other work. SSI-COV on LUMO (18 channels x 1e5
    samples, the whole ``analyse_signals``; ``benchmarks/modal_threads.py``) with two busy
    processes on the two cores: 9.3 s with the default threads, 4.4 s with one (26 s against
    5.4 s in an earlier run); idle, 2.3 s against 2.8 s.

    Parameters
    ----------
    fn : callable
        The function to wrap.

    Returns
    -------
    callable
        `fn` with the limit set for the duration of each call (restored after it).
    """

    @functools.wraps(fn)
    def bounded(*args, **kwargs):
        with _blas_controller().limit(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return bounded


@functools.lru_cache(maxsize=1)
def _blas_controller():
    """One :class:`threadpoolctl.ThreadpoolController` for the process: making one scans every
    loaded library (``threadpool_limits`` makes one per call), and the gap diagnosis enters
    :func:`one_blas_thread` for each of its thousands of probes. scipy.linalg is imported first
    so that its BLAS (scipy's own in its wheels) is among the libraries the controller limits."""
    import scipy.linalg  # noqa: F401 - load scipy's BLAS before the scan
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


__all__ = ["Identification", "modes_document", "positive_power_spectra", "polymax_oma", "auto_ssi", "auto_lscf", "reference_channels", "ssi_lags"]


@dataclass(frozen=True, eq=False)
class Identification:
    """Modes identified automatically, with what was rejected and how.

    Attributes
    ----------
    modes : ModalModel
        The physical modes; ``extra`` holds per-mode ``frequency_std_hz``, ``damping_std``,
        ``mpc``, ``mpd_deg`` and ``stable``.
    rejected : tuple of RejectedMode
        Candidates not reported, each with its reason.
    stabilization : Stabilization or None
        The stabilization diagram (SSI-COV, LSCF).
    settings : dict
        Every setting chosen (band, lags, orders, references, criteria, uncertainty method).
    lsfd : LSFDResult or None
        Residues and residuals (LSCF only), whose ``synthesize`` gives the model's FRFs.
    """

    modes: ModalModel
    rejected: tuple = ()
    stabilization: Any = None
    settings: dict = field(default_factory=dict)
    lsfd: Any = None

    def __repr__(self) -> str:
        return f"Identification({self.modes!r}, {len(self.rejected)} rejected)"

    def to_dict(self) -> dict:
        """The ``MODES.json`` document.

        Returns
        -------
        dict
            ``{"method", "points", "modes": [{"frequency_hz", "damping_ratio", "frequency_std_hz",
            "damping_std", "shape": {point: [re, im]}, "mpc", "mpd", "stable"}], "rejected":
            [{"frequency_hz", "damping_ratio", "reason"}], "settings"}``; NaN becomes None.
        """
        return modes_document(self.modes, self.rejected, self.settings)


def _num(v) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


def modes_document(modes: ModalModel, rejected: Sequence[RejectedMode] = (), settings: dict | None = None) -> dict:
    """A modal model as the ``MODES.json`` document of ``vibroscope modal``.

    Parameters
    ----------
    modes : ModalModel
        Per-mode ``extra`` arrays ``frequency_std_hz``, ``damping_std``, ``mpc``, ``mpd_deg`` and
        ``stable`` are used when present (else null / computed).
    rejected : sequence of RejectedMode, optional
    settings : dict, optional
        JSON-able settings.

    Returns
    -------
    dict
        See :meth:`Identification.to_dict`; frequencies in Hz, damping ratios dimensionless,
        MPD in degrees.
    """
    from vibroscope.modal._results import mpc

    ex = modes.extra
    n = len(modes)

    def col(key, default=np.nan):
        v = ex.get(key)
        return np.asarray(v) if isinstance(v, np.ndarray) and v.shape[:1] == (n,) else np.full(n, default)

    fstd, zstd, stable = col("frequency_std_hz"), col("damping_std"), col("stable", True)
    m = col("mpc") if "mpc" in ex else (mpc(modes.shapes) if n else np.zeros(0))
    d = col("mpd_deg")
    out = []
    for r in range(n):
        sh = modes.shapes[r]
        out.append({"frequency_hz": float(modes.natural_frequencies[r]),
                    "damping_ratio": _num(modes.damping_ratios[r]),
                    "frequency_std_hz": _num(fstd[r]), "damping_std": _num(zstd[r]),
                    "shape": {p: [float(v.real), float(v.imag)] for p, v in zip(modes.points, sh)},
                    "mpc": _num(m[r]), "mpd": _num(d[r]), "stable": bool(stable[r])})
    return {"method": modes.method, "points": list(modes.points), "modes": out,
            "rejected": [x.to_dict() for x in rejected],
            "normalisation": ex.get("normalisation", "unit_maximum"),
            "settings": dict(settings or {})}


def reference_channels(y: np.ndarray, n_ref: int = 6) -> list[int]:
    """The `n_ref` most linearly independent channels (pivoted QR of the correlation matrix).

    Parameters
    ----------
    y : ndarray, shape (n_channels, n_samples)
    n_ref : int, optional
        Default 6.

    Returns
    -------
    list of int
        Ascending channel indices; all channels when there are at most `n_ref`.
    """
    import scipy.linalg

    y = np.asarray(y, float)
    if y.shape[0] <= n_ref:
        return list(range(y.shape[0]))
    ok = np.isfinite(y).all(axis=0)  # missing samples (NaN): the instants where all are present
    if not ok.all():
        y = y[:, ok]
    R0 = np.corrcoef(y - y.mean(axis=1, keepdims=True))
    _, _, piv = scipy.linalg.qr(R0, pivoting=True)
    return sorted(int(i) for i in piv[:n_ref])


def ssi_lags(fs: float, f_low: float, n_samples: int, *, periods: float = 2.0) -> int:
    """Block rows of SSI-COV: `periods` periods of the lowest mode `f_low` (Hz), within
    [20, min(300, n_samples / 40)].

    Parameters
    ----------
    fs : float
        Sampling frequency in Hz.
    f_low : float
        Frequency of the lowest mode of interest in Hz.
    n_samples : int
        Record length in samples.
    periods : float, optional
        Periods of `f_low` the time lags should span; default 2.

    Returns
    -------
    int
        ``max(20, min(ceil(periods fs / f_low), 300, n_samples // 40))``.
    """
    want = int(np.ceil(periods * fs / max(f_low, 1e-12)))
    return int(max(20, min(want, 300, n_samples // 40)))


def line_spacing(frequencies: np.ndarray) -> float | None:
    """The median line spacing (Hz) of a frequency axis; None when it has fewer than two lines.

    Parameters
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Frequency axis in Hz.

    Returns
    -------
    float or None
        The median of the positive, finite spacings.
    """
    d = np.diff(np.asarray(frequencies, float))
    d = d[np.isfinite(d) & (d > 0)]
    return float(np.median(d)) if d.size else None


def _add_quality(mm: ModalModel) -> ModalModel:
    """`mm` with per-mode ``mpc`` and ``mpd_deg`` in its ``extra``."""
    from vibroscope.modal._results import mpc
    from vibroscope.modal.quality import mpd

    n = len(mm)
    extra = {**mm.extra, "mpc": mpc(mm.shapes) if n else np.zeros(0),
             "mpd_deg": np.atleast_1d(mpd(mm.shapes)) if n else np.zeros(0)}
    return dataclasses.replace(mm, extra=extra)


@one_blas_thread
def auto_ssi(
    signals: Signals,
    *,
    f_low: float,
    fmin: float | None = None,
    fmax: float | None = None,
    n_ref: int = 6,
    orders: Sequence[int] | None = None,
    damping_range: tuple[float, float] = DAMPING_RANGE,
    min_mpc: float = MIN_MPC,
    uncertainty: bool = True,
    select: Sequence[float] | None = None,
) -> Identification:
    """Output-only modes by SSI-COV with automatic settings and physical-mode selection.

    Parameters
    ----------
    signals : Signals
        The responses (already decimated to the band of interest: fs about 2.5–4 × `fmax`).
    f_low : float
        The lowest resonance (Hz), e.g. from :func:`vibroscope.modal.selection.response_band`;
        the covariance lags cover two of its periods.
    fmin, fmax : float, optional
        The band (Hz) modes are reported in; default 0 to 0.4 fs.
    n_ref : int, optional
        Reference channels (:func:`reference_channels`); default 6.
    orders : sequence of int, optional
        Model orders; default every 4th from 8 to ``min(120, n_lags · n_ref)``.
    damping_range : (float, float), optional
        Physical damping ratios (see :func:`vibroscope.modal.selection.select_modes`).
    min_mpc : float, optional
        Smallest MPC of a reported mode.
    uncertainty : bool, optional
        Estimate standard deviations by :func:`vibroscope.modal.uncertainty.ssi_bootstrap`.
    select : sequence of float, optional
        Take the modes at these frequencies (Hz) from the stabilization diagram
        (:func:`vibroscope.modal.selection.pick_poles`) instead of the automatic selection.

    Returns
    -------
    Identification

    See Also
    --------
    vibroscope.modal.ssi_cov : The stabilization diagram with settings of one's own.
    auto_lscf : The input-output counterpart (FRFs, LSCF and LSFD).
    vibroscope.modal.fdd : Output-only modes from the cross-spectral matrix.

    References
    ----------
    .. [1] B. Peeters and G. De Roeck, "Reference-based stochastic subspace identification for
       output-only modal analysis", Mechanical Systems and Signal Processing 13(6), 855–878, 1999.

    Examples
    --------
    One mode at 5 Hz with ζ = 0.02 (a resonator of quality factor ``Q = 1 / (2ζ) = 25`` driven by
    white noise), seen by two sensors in antiphase with 5 % noise each; nothing else is reported:

    >>> import numpy as np, scipy.signal
    >>> from vibroscope import Signals
    >>> rng = np.random.default_rng(0)
    >>> b, a = scipy.signal.iirpeak(5.0, Q=25.0, fs=100.0)
    >>> x = np.outer([1.0, -0.5], scipy.signal.lfilter(b, a, rng.standard_normal(20_000)))
    >>> x += 0.05 * x.std(axis=1, keepdims=True) * rng.standard_normal(x.shape)
    >>> ident = auto_ssi(Signals(data=x, fs=100.0, channels=["/a1.x", "/a2.x"]), f_low=5.0, uncertainty=False)
    >>> len(ident.modes), round(float(ident.modes.natural_frequencies[0]), 1)
    (1, 5.0)
    >>> round(float(ident.modes.damping_ratios[0]), 2), np.round(ident.modes.shapes.real, 2)
    (0.02, array([[ 1. , -0.5]]))
    """
    from vibroscope.modal.ssi import ssi_cov
    from vibroscope.modal.uncertainty import ssi_bootstrap

    y = np.asarray(signals.data, float)
    fs = signals.fs
    fmax = 0.4 * fs if fmax is None else float(fmax)
    n_lags = ssi_lags(fs, f_low, signals.n_samples)
    ref = reference_channels(y, n_ref)
    if orders is None:
        orders = range(8, int(min(120, n_lags * len(ref))) + 1, 4)
    st = ssi_cov(signals, n_lags=n_lags, orders=orders, ref=ref, max_damping=0.5)
    if select is not None:
        from vibroscope.modal.selection import Selection, pick_poles

        sel = Selection(pick_poles(st, select), (), {"selected_hz": list(select)})
    else:
        cand, unstable = cluster_poles(st)  # all of them: those outside the band are listed as such
        sel = select_modes(cand, fmin=fmin, fmax=fmax, damping_range=damping_range, min_mpc=min_mpc,
                           rejected=unstable)
    mm = _add_quality(sel.modes)
    unc_method = None
    if uncertainty and len(mm):
        order = int(np.max(mm.extra["order"]))
        try:
            n_blocks = int(min(10, max(4, signals.n_samples // (4 * (2 * n_lags + 1)))))
            u = ssi_bootstrap(y, fs, mm, n_lags=n_lags, order=order, ref=ref, n_blocks=n_blocks)
            mm = dataclasses.replace(mm, extra={**mm.extra, "frequency_std_hz": u.frequency_std_hz,
                                                "damping_std": u.damping_std})
            unc_method = u.method
        except ValueError as exc:  # record too short for blocks: the cluster spread stays
            unc_method = f"spread over the cluster's model orders (bootstrap impossible: {exc})"
    elif len(mm):
        unc_method = "spread over the cluster's model orders"
    settings = {"method": "ssi_cov", "fs": fs, "n_lags": n_lags, "orders": [int(o) for o in orders],
                "references": [signals.channels[i] for i in ref], "f_low_hz": f_low, "band_hz": [fmin, fmax],
                "uncertainty": unc_method, **{k: v for k, v in sel.criteria.items() if k != "band_hz"}}
    mm = dataclasses.replace(mm, extra={**mm.extra, "settings": settings, "stabilization": st})
    return Identification(mm, sel.rejected, st, settings)


@one_blas_thread
def auto_lscf(
    frf,
    *,
    fmin: float | None = None,
    fmax: float | None = None,
    orders: Sequence[int] | None = None,
    damping_range: tuple[float, float] = DAMPING_RANGE,
    min_mpc: float = MIN_MPC,
    min_coherence: float = 0.5,
    driving_point: tuple | None = None,
    select: Sequence[float] | None = None,
    min_peak_db: float | None = 30.0,
) -> Identification:
    """Modes from FRFs by LSCF/polyMAX, automatic pole selection and LSFD.

    Candidates within two lines of the FRF whose shapes agree (MAC ≥ 0.9) are one mode: the
    cluster that stands alone at the most model orders is kept, the others are rejected as its
    duplicates (``resolution_hz`` of :func:`vibroscope.modal.selection.select_modes`).

    Parameters
    ----------
    frf : FRF
        Measured FRFs ``H[f, output, input]``.
    fmin, fmax : float, optional
        The excited band in Hz (the input's, see :func:`vibroscope.modal.selection.excited_band`);
        default the FRF's axis (0 Hz excluded).
    orders : sequence of int, optional
        Polynomial orders; default those of :func:`vibroscope.modal.lscf`.
    damping_range : (float, float), optional
        Physical damping ratios.
    min_mpc : float, optional
        Smallest MPC of a reported mode.
    min_coherence : float, optional
        Smallest coherence at a mode where the FRF carries one.
    driving_point : (output, input), optional
        For unit-modal-mass shapes (see :func:`vibroscope.modal.lsfd`).
    select : sequence of float, optional
        Take the modes at these frequencies (Hz) from the stabilization diagram
        (:func:`vibroscope.modal.selection.pick_poles`) instead of the automatic selection.
    min_peak_db : float or None, optional
        A mode whose own peak (:meth:`~vibroscope.modal.lsfd.LSFDResult.peak_magnitude`) lies more
        than this many dB below the strongest mode's is rejected as weak; default 30 dB (the
        measured modes of the real data sets lie within 20 dB, the local and spurious ones 35–47 dB
        below). None keeps every stable, physical pole.

    Returns
    -------
    Identification
        With ``lsfd`` (residues, residuals; ``lsfd.synthesize()`` the model FRFs).

    See Also
    --------
    vibroscope.modal.lscf : The stabilization diagram with settings of one's own.
    vibroscope.modal.lsfd : The residue fit for given poles.
    auto_ssi : The output-only counterpart (SSI-COV).

    References
    ----------
    .. [1] B. Peeters, H. Van der Auweraer, P. Guillaume and J. Leuridan, "The PolyMAX
       frequency-domain method: a new standard for modal parameter estimation?", Shock and
       Vibration 11, 395–409, 2004.

    Examples
    --------
    A force through a resonator at 5 Hz with ζ = 0.02 (``iirpeak``, ``Q = 1 / (2ζ) = 25``):

    >>> import numpy as np, scipy.signal
    >>> from vibroscope import Signals, frf
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(100_000)
    >>> b, a = scipy.signal.iirpeak(5.0, Q=25.0, fs=100.0)
    >>> sig = Signals(data=np.vstack([u, scipy.signal.lfilter(b, a, u)]), fs=100.0, channels=["/f.x", "/a.x"],
    ...               units=["N", "m/s^2"])
    >>> ident = auto_lscf(frf(sig, "/f.x", nperseg=2048))
    >>> len(ident.modes), round(float(ident.modes.natural_frequencies[0]), 2)
    (1, 5.0)
    >>> round(float(ident.modes.damping_ratios[0]), 2)
    0.02
    """
    from vibroscope.modal.lscf import lscf
    from vibroscope.modal.lsfd import lsfd

    f = frf.frequencies
    lo = float(f[f > 0].min()) if fmin is None else float(fmin)
    hi = float(f.max()) if fmax is None else float(fmax)
    kw = {} if orders is None else {"orders": orders}
    st = lscf(frf, fmin=lo, fmax=hi, **kw)
    if select is not None:
        from vibroscope.modal.selection import Selection, pick_poles

        sel = Selection(pick_poles(st, select), (), {"selected_hz": list(select)})
    else:
        cand, unstable = cluster_poles(st, fmin=lo, fmax=hi)
        coh = None
        if np.any(np.isfinite(frf.coherence)):
            coh = (f, frf.coherence)
        # candidates within two lines of the FRF with the same shape are one (split) mode
        sel = select_modes(cand, fmin=lo, fmax=hi, damping_range=damping_range, min_mpc=min_mpc, coherence=coh,
                           min_coherence=min_coherence, rejected=unstable, resolution_hz=line_spacing(f))
    kept = sel.modes
    rejected = list(sel.rejected)
    res = None
    mm = kept
    if len(kept):
        res = lsfd(frf, kept.natural_frequencies, kept.damping_ratios, fmin=lo, fmax=hi, driving_point=driving_point)
        if select is None and min_peak_db is not None and len(kept) > 1:
            # a mode whose own peak is far below the strongest mode's is beyond the dynamic range the
            # measurement resolves (a local or barely excited mode, or an artefact): listed, not reported
            pk = res.peak_magnitude()
            rel = 20 * np.log10(np.maximum(pk, np.finfo(float).tiny) / pk.max())
            weak = rel < -min_peak_db
            if weak.any():
                for r in np.flatnonzero(weak):
                    rejected.append(RejectedMode(float(kept.natural_frequencies[r]), float(kept.damping_ratios[r]),
                                                 f"weak: its peak is {-rel[r]:.0f} dB below the strongest mode's "
                                                 f"(> {min_peak_db:g} dB)"))
                from vibroscope.modal.selection import subset_modes

                kept = subset_modes(kept, np.flatnonzero(~weak))
                res = lsfd(frf, kept.natural_frequencies, kept.damping_ratios, fmin=lo, fmax=hi,
                           driving_point=driving_point)
        mm = res.modal_model(driving_point=driving_point)
        extra = {**kept.extra, **mm.extra}
        mm = dataclasses.replace(mm, extra=extra)
    mm = _add_quality(mm)
    # the spread of a cluster over model orders is no statistical uncertainty: not reported as one
    nan = np.full(len(mm), np.nan)
    mm = dataclasses.replace(mm, extra={**mm.extra, "frequency_std_hz": nan, "damping_std": nan})
    settings = {"method": "lscf", "band_hz": [lo, hi], "orders": list(st.settings.get("orders", [])),
                "uncertainty": ("not estimated for FRFs (vibroscope.modal.uncertainty.lscf_bootstrap gives the "
                                "random part from a record)") if len(mm) else None,
                **{k: v for k, v in sel.criteria.items() if k != "band_hz"}}
    mm = dataclasses.replace(mm, extra={**mm.extra, "settings": settings, "stabilization": st})
    return Identification(mm, tuple(sorted(rejected, key=lambda r: r.natural_frequency)), st, settings, res)


def positive_power_spectra(signals: Signals, *, n_lags: int, ref: Sequence[int] | None = None,
                           final_window: float = 0.01):
    """Positive power spectra of output-only responses: the FRF-like input of polyMAX for OMA.

    The output correlations ``R(τ)`` (lags ``0 … n_lags − 1``, :func:`~vibroscope.modal.ssi.output_covariances`)
    are weighted by an exponential window ``w(τ) = exp(−σ τ)`` that decays to `final_window` at the
    last lag, the zero lag halved, and Fourier transformed. Under white excitation these half
    spectra have the structure's poles shifted by ``−σ`` (the window adds ``σ`` to the decay
    rate), which :func:`polymax_oma` removes (Peeters & Van der Auweraer 2005).

    Parameters
    ----------
    signals : Signals
        Responses (n_channels, n_samples), ``fs`` in Hz.
    n_lags : int
        Correlation lags: the spectra's resolution is ``fs / n_lags``.
    ref : sequence of int, optional
        Reference channels (the "inputs"); default :func:`reference_channels`.
    final_window : float, optional
        Value of the exponential window at the last lag; default 0.01.

    Returns
    -------
    (FRF, sigma)
        Half spectra ``S⁺[f, output, reference]`` (estimator ``"positive_power_spectra"``, kind
        None) and the window's decay rate ``σ`` in 1/s.

    References
    ----------
    .. [1] B. Peeters and H. Van der Auweraer, "PolyMAX: a revolution in operational modal
       analysis", Proc. 1st International Operational Modal Analysis Conference, Copenhagen, 2005.
    """
    from vibroscope.modal.ssi import output_covariances
    from vibroscope.spectral import FRF

    from vibroscope.modal.ssi import center

    y = center(np.asarray(signals.data, float))
    ref = reference_channels(y) if ref is None else list(ref)
    R = output_covariances(y, n_lags, ref)
    fs = signals.fs
    sigma = -np.log(final_window) * fs / (n_lags - 1)
    w = np.exp(-sigma * np.arange(n_lags) / fs)
    Rw = R * w[:, None, None]
    Rw[0] *= 0.5
    S = np.fft.rfft(Rw, n=2 * n_lags, axis=0)  # Σ R(τ) w(τ) e^{−jωτ}: a causal response's spectrum
    f = np.fft.rfftfreq(2 * n_lags, 1 / fs)
    h = FRF(frequencies=f, H=S, coherence=np.full((f.size, y.shape[0]), np.nan),
            inputs=tuple(signals.channels[i] for i in ref),
            outputs=tuple(signals.channels), estimator="positive_power_spectra", kind=None, units="",
            settings={"n_lags": n_lags, "sigma": sigma})
    return h, float(sigma)


@one_blas_thread
def polymax_oma(signals: Signals, *, f_low: float, fmin: float | None = None, fmax: float | None = None,
                n_ref: int = 6) -> Identification:
    """Output-only modes by polyMAX on the positive power spectra: the cross-check of SSI-COV.

    Parameters
    ----------
    signals : Signals
        Responses, decimated to the band of interest.
    f_low : float
        Lowest resonance (Hz): the spectra resolve it with 20 lines per Hz-width of ``f_low``
        (``n_lags = 20 fs / f_low``, at most a quarter of the record).
    fmin, fmax : float, optional
        Band in Hz; default up to 0.4 fs.
    n_ref : int, optional
        Reference channels.

    Returns
    -------
    Identification
        Method ``"polymax_oma"``; damping corrected for the exponential window.

    References
    ----------
    .. [1] B. Peeters and H. Van der Auweraer, "PolyMAX: a revolution in operational modal
       analysis", Proc. 1st International Operational Modal Analysis Conference, Copenhagen, 2005.
    """
    from vibroscope.modal.lscf import lscf

    fs = signals.fs
    fmax = 0.4 * fs if fmax is None else float(fmax)
    n_lags = int(min(20 * fs / max(f_low, 1e-9), signals.n_samples // 4))
    ref = reference_channels(np.asarray(signals.data), n_ref)
    h, sigma = positive_power_spectra(signals, n_lags=n_lags, ref=ref)
    lo = fmin if fmin is not None else 0.5 * f_low
    st = lscf(h, fmin=lo, fmax=fmax)
    # remove the window's damping: λ = λ' + σ
    wn = 2 * np.pi * st.frequency
    lam = -st.damping * wn + 1j * wn * np.sqrt(np.maximum(1 - st.damping**2, 0)) + sigma
    f = np.abs(lam) / (2 * np.pi)
    z = -lam.real / np.abs(lam)
    st = dataclasses.replace(st, frequency=f, damping=z,
                             settings={**st.settings, "method": "polymax_oma", "window_sigma": sigma})
    cand, unstable = cluster_poles(st)
    sel = select_modes(cand, fmin=fmin, fmax=fmax, rejected=unstable, resolution_hz=line_spacing(h.frequencies))
    mm = _add_quality(sel.modes)
    settings = {"method": "polymax_oma", "n_lags": n_lags, "window_sigma_per_s": sigma,
                "references": [signals.channels[i] for i in ref], "band_hz": [fmin, fmax],
                "uncertainty": "spread over the cluster's model orders"}
    mm = dataclasses.replace(mm, extra={**mm.extra, "settings": settings, "stabilization": st})
    return Identification(mm, sel.rejected, st, settings)
