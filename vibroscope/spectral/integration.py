"""From acceleration to velocity and displacement: drift-free integration, the ISO 20816-1
vibration severity, and the operating deflection shape at one frequency.

These are the numbers behind the founding paper's acquisition instrument, which shows
acceleration, velocity and displacement against time and the relative movement of the robot's
bodies at a resonance. Imports nothing of vibroscope but :mod:`vibroscope.signals` (and this room).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.fft
import scipy.signal
from scipy.integrate import cumulative_trapezoid

from vibroscope._checks import check_option, read_only
from vibroscope.signals import Signals, true_runs
from vibroscope.spectral._results import FRF, CrossSpectralMatrix, channel_index

__all__ = ["integrate", "velocity_and_displacement", "default_f_cut", "vibration_severity", "Severity", "ods", "OperatingShape",
           "highpass_gain"]

#: order of the Butterworth high-pass (applied forward and backward: zero phase, 2×4 poles)
BUTTER_ORDER = 4
#: standard gravity in m/s² (for channels in g)
G_N = 9.80665

#: the spellings of m/s² taken as acceleration units
ACC_UNITS = {"m/s^2", "m/s²", "m/s2", "m s^-2", "m·s^-2", "m*s^-2", "m.s^-2"}
_VEL_UNITS = {"m/s", "m s^-1", "m·s^-1", "m*s^-1"}
_INTEGRAL_UNIT = {**{u: "m/s" for u in ACC_UNITS}, **{u: "m" for u in _VEL_UNITS}}


def _integral_unit(unit: str, order: int) -> str:
    """Unit of the `order`-fold time integral of `unit` (``'m/s^2'`` → ``'m/s'`` → ``'m'``)."""
    u = unit.strip()
    for k in range(order):
        if u == "":
            return ""
        if u in _INTEGRAL_UNIT:
            u = _INTEGRAL_UNIT[u]
        else:  # unknown: append the remaining powers of s
            rest = order - k
            return f"{u}·s" if rest == 1 else f"{u}·s{'²³⁴'[rest - 2] if rest <= 4 else f'^{rest}'}"
    return u


def default_f_cut(fs: float, n_samples: int) -> float:
    """The default high-pass cut-off of :func:`integrate`: ``max(10 / T, 1 Hz)``.

    Ten cycles over the record ``T = n_samples / fs`` at least (so the high-pass transients at
    the record's ends, about ``1 / f_cut`` long, stay short against it), and never below 1 Hz:
    below that an accelerometer on a moving robot sees gravity re-projected by slow attitude
    changes, bias drift and the motion itself rather than vibration.

    Parameters
    ----------
    fs : float
        Sampling frequency in Hz.
    n_samples : int
        Record length in samples.

    Returns
    -------
    float
        Cut-off in Hz.
    """
    return max(10.0 * float(fs) / max(int(n_samples), 1), 1.0)


def highpass_gain(frequencies, f_cut: float) -> np.ndarray:
    """Magnitude of the zero-phase high-pass applied once per integration.

    ``W(f) = 1 / (1 + (f_cut / f)^8)``: a 4th-order Butterworth high-pass run forward and
    backward (:func:`scipy.signal.sosfiltfilt`), i.e. ``|H_B4(f)|²``: −6 dB at `f_cut`,
    1 − 1.5e-4 at ``3 f_cut``, no phase shift.

    Parameters
    ----------
    frequencies : array_like
        Frequencies in Hz (≥ 0).
    f_cut : float
        Cut-off in Hz.

    Returns
    -------
    ndarray, shape like `frequencies`
        Gains in [0, 1]; 0 at 0 Hz.
    """
    frequencies = np.abs(np.asarray(frequencies, dtype=float))
    out = np.zeros(frequencies.shape)
    pos = frequencies > 0
    out[pos] = 1.0 / (1.0 + (f_cut / frequencies[pos]) ** (2 * BUTTER_ORDER))
    return out


def _check_f_cut(f_cut, fs: float, n: int) -> float:
    if f_cut is None:
        f_cut = default_f_cut(fs, n)
    f_cut = float(f_cut)
    if not np.isfinite(f_cut) or not 0 < f_cut < fs / 2:
        raise ValueError(f"{f_cut=} Hz must lie between 0 and the Nyquist frequency {fs / 2:g} Hz")
    return f_cut


def _integrate_frequency(x: np.ndarray, fs: float, f_cut: float) -> np.ndarray:
    """One integration of the rows of `x` (length ``n``) as the FFT on the antisymmetric extension
    ``[x, −x reversed]`` (length ``2n``) defines it, computed by the pair of length-``n`` real
    trigonometric transforms that this FFT reduces to (half the work, the same numbers to ~1e-14
    of the RMS).

    With ``S = DST-II(x)`` (scipy's unnormalised convention), the extension's DFT is
    ``X[j] = −i e^{iπj/2n} S[j-1]`` for ``j = 1..n`` (``X[0] = 0``); multiplied by the purely
    imaginary ``H[j] = W(f_j) / (i 2π f_j)``, ``f_j = j fs / 2n``, the inverse DFT is even about
    the record's end and its first half is ``−DCT-III(c) / 2n`` with ``c[0] = 0``,
    ``c[j] = S[j-1] W(f_j) / (2π f_j)`` for ``j = 1..n−1`` (the Nyquist bin ``j = n`` zero)
    [Britanak, Yip & Rao, *Discrete Cosine and Sine Transforms*, Academic Press, 2007, ch. 2].
    """
    n = x.shape[-1]
    f = np.arange(1, n + 1) * (fs / (2 * n))
    g = highpass_gain(f, f_cut) / (2 * np.pi * f)
    S = scipy.fft.dst(x, type=2, axis=-1, workers=-1)
    c = np.empty_like(S)
    c[:, 0] = 0.0
    np.multiply(S[:, :-1], g[:-1], out=c[:, 1:])
    return scipy.fft.dct(c, type=3, axis=-1, workers=-1, overwrite_x=True) * (-1.0 / (2 * n))


def _integrate_highpass(x: np.ndarray, fs: float, f_cut: float) -> np.ndarray:
    """One cumulative trapezoidal integration of the rows of `x`, then the zero-phase high-pass."""
    n = x.shape[-1]
    sos = scipy.signal.butter(BUTTER_ORDER, f_cut, "highpass", fs=fs, output="sos")
    y = cumulative_trapezoid(x, dx=1.0 / fs, axis=-1, initial=0.0)
    padlen = min(n - 1, int(np.ceil(3.0 * fs / f_cut)))
    return scipy.signal.sosfiltfilt(sos, y, axis=-1, padtype="even", padlen=padlen)


def integrate(signals: Signals, *, order: Literal[1, 2] = 1, f_cut: float | None = None,
              method: Literal["frequency", "highpass"] = "frequency") -> Signals:
    """Integrate accelerations to velocities (``order=1``) or displacements (``order=2``), drift-free.

    Double integration of a measured acceleration amplifies everything slow without bound: an
    offset becomes a parabola, sensor drift a cubic. Only the content above a cut-off `f_cut` is
    recovered; below it a zero-phase high-pass removes it. Each row is first freed of its
    least-squares straight line (``scipy.signal.detrend(type='linear')``: offset and linear drift).

    Parameters
    ----------
    signals : Signals
        ``data`` shape (n_channels, n_samples), accelerations in m/s² (or any quantity: the
        result is its time integral), ``fs`` in Hz.
    order : {1, 2}, optional
        Number of integrations: 1 gives velocity (m/s), 2 displacement (m).
    f_cut : float, optional
        High-pass cut-off in Hz, ``0 < f_cut < fs / 2``. Default :func:`default_f_cut`:
        ``max(10 / T, 1 Hz)`` for a record of ``T`` s. Content at ``f >= 3 f_cut`` is kept to
        better than 0.02 % per integration; content at `f_cut` is halved per integration.
    method : {'frequency', 'highpass'}, optional
        ``'frequency'`` (default): each integration multiplies the FFT of the row's antisymmetric
        extension (see Notes) by ``W(f) / (j 2π f)``. ``'highpass'``: each integration is a
        cumulative trapezoid (:func:`scipy.integrate.cumulative_trapezoid`) followed by the
        same high-pass in the time domain (:func:`scipy.signal.sosfiltfilt`, even padding of
        ``3 / f_cut`` s).

    Returns
    -------
    Signals
        Same channels, ``fs`` and ``t0``; ``data`` shape (n_channels, n_samples) of the
        integrals. Units: ``'m/s^2'``/``'m/s²'`` → ``'m/s'`` → ``'m'``; an unknown unit ``u``
        becomes ``'u·s'`` (``'u·s²'`` for order 2), ``''`` stays ``''``.
        ``meta["integration"] = {"order", "f_cut_hz", "method", "highpass", "detrend"}``.

    Raises
    ------
    ValueError
        If `order` or `method` is not an allowed value, `f_cut` is not between 0 and ``fs / 2``,
        or the record has fewer than 4 samples.

    Missing samples (NaN, a gap in the log) are never bridged: each stretch of finite samples of
    a row is detrended and integrated on its own, as a record of its own (with its own edge
    zones, below), and the missing samples stay NaN (as do stretches of fewer than 4 samples);
    ``meta["integration"]["gaps"]`` then says so.

    Notes
    -----
    The high-pass, applied once per integration in both methods, is
    ``W(f) = 1 / (1 + (f_cut / f)^8)`` (:func:`highpass_gain`), the magnitude of a 4th-order
    Butterworth high-pass run forward and backward: zero phase, −6 dB at `f_cut`. For
    ``order=2`` the net gain is ``W(f)²``. The two methods thus apply the same operator
    ``(W(f) / (j 2π f))^order`` and differ only in how they treat the record's ends and in the
    integration rule:

    - ``'frequency'`` integrates the row extended to twice its length as ``[x, −x reversed]``
      (a sine series). The extension has zero mean and is periodic, so the inverse FFT has no
      wrap-around ramp, and its integral is even about both ends, so the high-pass sees no step
      there (what a plain FFT of a non-periodic record suffers from). The division by ``jω`` is
      exact at every frequency; the Nyquist bin is set to zero.
    - ``'highpass'`` uses the trapezoid rule, whose gain ``(ωΔ/2) / tan(ωΔ/2)`` (``Δ = 1/fs``)
      falls short of ``1/(jω)`` by ``(ωΔ)² / 12``: 0.16 % at ``fs / 20``, 0.8 % at ``fs / 10``,
      per integration.

    Both leave edge zones of about ``1 / f_cut`` at each end of the record where the unknown
    signal outside the record matters. Measured on a sum of sines at 3.3–21.7 Hz with an offset
    and drifts, ``f_cut`` = 1 Hz, 60 s at 1 kHz: RMS error 1.1 % (velocity) and 2.9 %
    (displacement) over the whole record, 0.2 % / 0.6 % beyond 0.6 s from the ends, < 0.03 %
    beyond 3 s, for either method.

    References
    ----------
    .. [1] A. Brandt, *Noise and Vibration Analysis: Signal Analysis and Experimental
       Procedures*, Wiley, 2011, ch. 3 (time data analysis: integration and differentiation of
       measured signals).
    .. [2] K. Worden, "Data processing and experiment design for the restoring force surface
       method, Part I: integration and differentiation of measured time data", Mechanical
       Systems and Signal Processing 4(4), 295–319, 1990.

    Examples
    --------
    A 10 Hz acceleration of amplitude 1 m/s² on a 2 m/s² offset gives a velocity of amplitude
    ``1 / (2π·10)`` m/s:

    >>> import numpy as np
    >>> from vibroscope import Signals
    >>> fs = 1000.0
    >>> t = np.arange(20000) / fs
    >>> acc = Signals(data=2.0 + np.sin(2 * np.pi * 10 * t), fs=fs, channels=["/imu.z"], units=["m/s^2"])
    >>> vel = integrate(acc)
    >>> vel.units, round(float(np.max(np.abs(vel.data[0, 2000:-2000])) * 2 * np.pi * 10), 3)
    (('m/s',), 1.0)
    """
    check_option("order", order, (1, 2))
    return _integrals(signals, order, f_cut, method)[-1]


def velocity_and_displacement(signals: Signals, *, f_cut: float | None = None,
                              method: Literal["frequency", "highpass"] = "frequency") -> tuple[Signals, Signals]:
    """Velocity and displacement of accelerations in one pass: ``(integrate(signals, order=1),
    integrate(signals, order=2))``, the same numbers, the first integration done once.

    Parameters
    ----------
    signals : Signals
        ``data`` shape (n_channels, n_samples), accelerations in m/s², ``fs`` in Hz.
    f_cut : float, optional
        High-pass cut-off in Hz (see :func:`integrate`).
    method : {'frequency', 'highpass'}, optional
        See :func:`integrate`.

    Returns
    -------
    tuple of Signals
        (velocity, displacement), each as :func:`integrate` returns it (units m/s and m for
        m/s²), equal to it bit for bit.

    Raises
    ------
    ValueError
        As :func:`integrate`.
    """
    vel, disp = _integrals(signals, 2, f_cut, method)
    return vel, disp


def _integrals(signals: Signals, order: int, f_cut, method: str) -> list[Signals]:
    """The integrals of orders 1..`order` of `signals` (:func:`integrate`), each step done once."""
    check_option("method", method, ("frequency", "highpass"))
    fs = signals.fs
    n = signals.n_samples
    if n < 4:
        raise ValueError(f"the record is too short to integrate: {n=} samples")
    f_cut = _check_f_cut(f_cut, fs, n)
    step = _integrate_frequency if method == "frequency" else _integrate_highpass

    def run(x: np.ndarray) -> list[np.ndarray]:
        x = scipy.signal.detrend(x, axis=-1, type="linear")
        out = []
        for _ in range(order):
            x = step(x, fs, f_cut)
            out.append(x)
        return out

    data = np.asarray(signals.data, dtype=float)
    finite = np.isfinite(data)
    stretches = None
    if finite.all():
        xs = run(data)
    else:  # a gap is not bridged: each stretch between gaps is integrated on its own, the gaps stay NaN
        xs = [np.full(data.shape, np.nan) for _ in range(order)]
        stretches = 0
        for r in range(data.shape[0]):
            for a, b in zip(*true_runs(finite[r])):
                if b - a >= 4:  # shorter: too short to integrate, left NaN
                    for x, y in zip(xs, run(data[r : r + 1, a:b])):
                        x[r, a:b] = y[0]
                    stretches += 1
    out = []
    for k, x in enumerate(xs, start=1):
        info = {
            "order": k,
            "f_cut_hz": f_cut,
            "method": method,
            "highpass": f"zero-phase Butterworth order {BUTTER_ORDER} forward-backward per integration, "
                        f"|W|=1/(1+(f_cut/f)^{2 * BUTTER_ORDER}), -6 dB at {f_cut:.4g} Hz",
            "detrend": "linear",
        }
        if stretches is not None:
            info["gaps"] = (f"{stretches} stretches between missing samples integrated one by one (each detrended, "
                            f"with its own edge zones); missing samples and stretches under 4 samples are NaN")
        out.append(Signals(data=x, fs=fs, channels=signals.channels,
                           units=[_integral_unit(u, k) for u in signals.units],
                           t0=signals.t0,
                           meta={**signals.meta, "integration": info}))
    return out


# ---------------------------------------------------------------------------------------------
# vibration severity
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class Severity:
    """ISO 20816-1 vibration severity: broadband RMS velocity per channel.

    Attributes
    ----------
    channels : tuple of str
        Channel names.
    velocity_rms_mm_s : ndarray, shape (n_channels,)
        RMS velocity in mm/s over `band_hz`.
    band_hz : tuple of float
        ``(fmin, fmax)`` in Hz actually integrated over (`fmax` is clipped to ``fs / 2``).
    method : str
        How it was computed.
    note : str
        Deviations from the standard's band or assumptions about units; ``''`` when none.
    settings : dict
        ``fs``, ``nperseg``, ``noverlap``, ``window``, ``detrend``, ``df_hz``, ``n_averages``.
    """

    channels: tuple[str, ...]
    velocity_rms_mm_s: np.ndarray
    band_hz: tuple[float, float]
    method: str
    note: str = ""
    settings: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "velocity_rms_mm_s", read_only(self.velocity_rms_mm_s, float))
        object.__setattr__(self, "band_hz", (float(self.band_hz[0]), float(self.band_hz[1])))

    def __getitem__(self, channel: str | int) -> float:
        """RMS velocity of one channel (name or index) in mm/s.

        Raises
        ------
        KeyError
            If there is no such channel; the message names the valid ones.
        """
        return float(self.velocity_rms_mm_s[channel_index(self.channels, channel)])

    def __repr__(self) -> str:
        vals = ", ".join(f"{c}: {v:.3g}" for c, v in zip(self.channels[:4], self.velocity_rms_mm_s[:4]))
        more = ", ..." if len(self.channels) > 4 else ""
        return (f"Severity(v_rms [mm/s] over {self.band_hz[0]:g}–{self.band_hz[1]:g} Hz: {vals}{more}"
                + (f"; {self.note}" if self.note else "") + ")")


def vibration_severity(signals: Signals, *, band: tuple[float, float] = (10.0, 1000.0)) -> Severity:
    """Vibration severity after ISO 20816-1: the RMS velocity over 10–1000 Hz, in mm/s.

    The velocity PSD is the acceleration PSD divided by ``(2π f)²``; its integral over the band
    (Parseval) is the mean square velocity. No time-domain integration, hence no drift.

    Parameters
    ----------
    signals : Signals
        Accelerations, ``data`` shape (n_channels, n_samples), in m/s² (``'m/s^2'``, ``'m/s²'``;
        ``'g'`` is converted with 9.80665 m/s²; ``''`` is taken as m/s² and said so in ``note``).
    band : tuple of float, optional
        ``(fmin, fmax)`` in Hz; the standard's broadband range is 10–1000 Hz (2–1000 Hz for
        machines below 600 r/min). `fmax` above ``fs / 2`` is clipped to ``fs / 2``, and
        ``note`` says so.

    Returns
    -------
    Severity
        ``velocity_rms_mm_s`` shape (n_channels,).

    Raises
    ------
    ValueError
        If a channel's unit is not an acceleration, or the band is empty or starts at or
        above ``fs / 2``.

    Notes
    -----
    The PSD is Welch's (Hann, 50 % overlap, linear detrend per segment, one-sided density)
    with segments of ``nperseg = min(n_samples, 20 fs / fmin)`` rounded up to a fast FFT size:
    ``Δf <= fmin / 20`` (0.5 Hz for the standard band) so a tone just outside the band leaks
    less than −80 dB into it. Then

    ``v_rms² = Σ_{fmin <= f_k <= fmax} G_aa(f_k) / (2π f_k)² · Δf``.

    A tone of amplitude ``A`` (m/s²) at ``f`` inside the band gives ``A / (2π f √2)`` m/s.

    References
    ----------
    .. [1] ISO 20816-1:2016, *Mechanical vibration — Measurement and evaluation of machine
       vibration — Part 1: General guidelines*, §3 and Annex (broadband r.m.s. velocity,
       10–1000 Hz).
    .. [2] P. D. Welch, "The use of fast Fourier transform for the estimation of power
       spectra", IEEE Trans. Audio Electroacoust. 15(2), 70–73, 1967.

    Examples
    --------
    >>> import numpy as np
    >>> from vibroscope import Signals
    >>> fs = 4000.0
    >>> t = np.arange(40000) / fs
    >>> s = Signals(data=10.0 * np.sin(2 * np.pi * 50 * t), fs=fs, channels=["/imu.z"], units=["m/s^2"])
    >>> round(vibration_severity(s)["/imu.z"], 2)  # 10 / (2π·50·√2) m/s = 22.51 mm/s
    22.51
    """
    fs = signals.fs
    n = signals.n_samples
    fmin, fmax = (float(b) for b in band)
    if not (np.isfinite(fmin) and np.isfinite(fmax)) or not 0 < fmin < fmax:
        raise ValueError(f"{band=} must be (fmin, fmax) with 0 < fmin < fmax in Hz")
    notes = []
    if fmax > fs / 2:
        notes.append(f"band upper edge {fmax:g} Hz above the Nyquist frequency: integrated up to "
                     f"fs/2 = {fs / 2:g} Hz only")
        fmax = fs / 2
    if fmin >= fmax:
        raise ValueError(f"band lower edge {fmin:g} Hz is not below fs/2 = {fs / 2:g} Hz")
    scale = np.ones(signals.n_channels)
    assumed = []
    for k, u in enumerate(signals.units):
        u = u.strip()
        if u in ACC_UNITS:
            continue
        if u == "g":
            scale[k] = G_N
        elif u == "":
            assumed.append(signals.channels[k])
        else:
            raise ValueError(f"channel {signals.channels[k]!r} has unit {u!r}; vibration severity needs "
                             "accelerations in m/s^2 (or g)")
    if assumed:
        notes.append(f"no unit on {len(assumed)} channel(s), taken as m/s^2")
    nperseg = min(n, scipy.fft.next_fast_len(int(np.ceil(20.0 * fs / fmin))))
    if nperseg < 8:
        raise ValueError(f"the record is too short for a spectrum: {n=} samples")
    noverlap = nperseg // 2
    from vibroscope.spectral.estimators import welch

    # NaN-aware: segments touching a missing sample are skipped (see welch)
    sp = welch(np.asarray(signals.data) * scale[:, None], fs, window="hann", nperseg=nperseg,
               noverlap=noverlap, detrend="linear", scaling="density")
    f, P = sp.frequencies, sp.values
    df = float(f[1] - f[0])
    if df > fmin / 4:
        notes.append(f"record of {n / fs:g} s resolves only {df:.3g} Hz: the band edge at {fmin:g} Hz is coarse")
    sel = (f >= fmin) & (f <= fmax) & (f > 0)
    pv = P[:, sel] / (2 * np.pi * f[sel]) ** 2
    v_rms = np.sqrt(np.sum(pv, axis=-1) * df)
    n_avg = int(sp.n_averages.min())
    settings = dict(fs=fs, nperseg=int(nperseg), noverlap=int(noverlap), window="hann", detrend="linear",
                    df_hz=df, n_averages=int(n_avg))
    method = "Welch PSD of acceleration / (2πf)², integrated over the band (Parseval)"
    return Severity(channels=signals.channels, velocity_rms_mm_s=1000.0 * v_rms, band_hz=(fmin, fmax), method=method,
                    note="; ".join(notes), settings=settings)


# ---------------------------------------------------------------------------------------------
# operating deflection shape
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, kw_only=True)
class OperatingShape:
    """The operating deflection shape (ODS) of the measurement points at one frequency.

    Attributes
    ----------
    frequency : float
        The spectral line used, in Hz (the nearest to `requested_frequency`).
    shape : ndarray, complex, shape (n_points,)
        Relative amplitude and phase of the points, normalised to unit maximum modulus with the
        `reference` point's entry real and positive.
    points : tuple of str
        Point (channel) names, the entries of `shape`.
    source : {'frf', 'csd'}
        What it was taken from.
    reference : str
        The point whose phase is zero in `shape`.
    values : ndarray, complex, shape (n_points,)
        The un-normalised ODS in `units`: ``H[f, :, input]`` (FRF), or
        ``G[f, ref, :] / sqrt(G[f, ref, ref])`` (CSD: the points' linear spectra with phases
        relative to the reference).
    units : str
        Units of `values` (the FRF's; ``'u/√Hz'`` for a CSD density, ``'u'`` for a power spectrum).
    requested_frequency : float
        The frequency asked for, in Hz.
    input : str or None
        The FRF's input (excitation) channel; None for a CSD.
    """

    frequency: float
    shape: np.ndarray
    points: tuple[str, ...]
    source: Literal["frf", "csd"]
    reference: str
    values: np.ndarray
    units: str = ""
    requested_frequency: float = float("nan")
    input: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "frequency", float(self.frequency))
        object.__setattr__(self, "shape", read_only(self.shape, complex))
        object.__setattr__(self, "values", read_only(self.values, complex))
        object.__setattr__(self, "points", tuple(str(p) for p in self.points))

    def plot(self, coords=None, **kwargs):
        """Draw it like a mode shape; imports matplotlib lazily through
        :func:`vibroscope.viewers.figures.plot_ods` (arguments passed on).

        Parameters
        ----------
        coords : mapping, optional
            Sensor positions and directions (see
            :func:`vibroscope.viewers._common.sensor_geometry`); points on a line when None.
        **kwargs
            Passed to :func:`~vibroscope.viewers.figures.plot_ods` (``fig``,
            ``true_modes``).

        Returns
        -------
        matplotlib.figure.Figure
        """
        from vibroscope._plotting import draw

        return draw("plot_ods", self, coords, **kwargs)

    def __repr__(self) -> str:
        return (f"OperatingShape({self.frequency:.4g} Hz from {self.source}, {len(self.points)} points, "
                f"reference {self.reference!r})")


def _line(frequencies: np.ndarray, frequency: float) -> int:
    f = np.asarray(frequencies, dtype=float)
    if f.size == 0:
        raise ValueError("the frequency axis is empty")
    fr = float(frequency)
    if not np.isfinite(fr) or fr < f[0] or fr > f[-1]:
        raise ValueError(f"{frequency=} Hz is outside the frequency axis [{f[0]:g}, {f[-1]:g}] Hz")
    return int(np.argmin(np.abs(f - fr)))


def _index(names: tuple[str, ...], key: str | int, what: str) -> int:
    if isinstance(key, (int, np.integer)):
        if not -len(names) <= key < len(names):
            raise KeyError(f"{what} index {key} out of range for {len(names)} {what}s")
        return int(key) % len(names)
    try:
        return names.index(key)
    except ValueError:
        raise KeyError(f"no {what} {key!r}; {what}s are {list(names)}") from None


def ods(source: FRF | CrossSpectralMatrix, frequency: float, *, reference: str | int | None = None,
        input: str | int = 0) -> OperatingShape:
    """Operating deflection shape at one frequency, from an FRF or a cross-spectral matrix.

    Parameters
    ----------
    source : FRF or CrossSpectralMatrix
        An FRF ``H[f, output, input]`` (the shape is the outputs' column of one input) or the
        cross-spectral matrix ``G[f, i, j]`` of the response channels (output-only).
    frequency : float
        Frequency in Hz; the nearest spectral line is used.
    reference : str or int, optional
        The point (output / channel name or index) whose phase is the zero of the shape.
        Default: for a CSD the channel with the largest auto-spectrum at that line, for an
        FRF the output with the largest ``|H|``.
    input : str or int, optional
        The FRF's input (name or index); default the first. Ignored for a CSD.

    Returns
    -------
    OperatingShape
        ``shape`` complex (n_points,) of unit maximum modulus, ``reference`` entry real
        positive; ``values`` un-normalised.

    Raises
    ------
    ValueError
        If `frequency` is outside the source's frequency axis, or the reference
        auto-spectrum is zero at that line.
    KeyError
        If `reference` or `input` names no channel.
    TypeError
        If `source` is neither an FRF nor a CrossSpectralMatrix.

    Notes
    -----
    From a CSD with scipy's convention ``G[f, i, j] = conj(X_i)·X_j`` the ODS is the reference
    row ``G[f, r, :] / sqrt(G[f, r, r])``: for fully coherent channels its entry ``i`` is
    ``|X_i| exp(j(φ_i − φ_r))``, the amplitude of point ``i`` (in ``unit/√Hz``) with its phase
    relative to the reference. (The column ``G[f, :, r]`` is its complex conjugate: the same
    shape turning the other way.) Near a lightly damped, well separated resonance the ODS
    approaches the mode shape; elsewhere it is a mix of modes and forcing.

    References
    ----------
    .. [1] M. H. Richardson, "Is it a mode shape, or an operating deflection shape?", Sound and
       Vibration 31(1), 54–61, 1997.
    .. [2] J. S. Bendat and A. G. Piersol, *Random Data: Analysis and Measurement Procedures*,
       4th ed., Wiley, 2010, §5.2 (cross-spectral density functions).
    """
    if isinstance(source, FRF):
        k = _line(source.frequencies, frequency)
        i_in = _index(source.inputs, input, "input")
        vals = np.array(source.H[k, :, i_in], dtype=complex)
        points = source.outputs
        ref = int(np.nanargmax(np.abs(vals))) if reference is None else _index(points, reference, "output")
        units, kind, in_name = source.units, "frf", source.inputs[i_in]
    elif isinstance(source, CrossSpectralMatrix):
        k = _line(source.frequencies, frequency)
        points = source.channels
        auto = np.real(np.diagonal(source.G[k]))
        ref = int(np.argmax(auto)) if reference is None else _index(points, reference, "channel")
        if not auto[ref] > 0:
            raise ValueError(f"the auto-spectrum of reference {points[ref]!r} is zero at "
                             f"{source.frequencies[k]:g} Hz")
        vals = np.array(source.G[k, ref, :], dtype=complex) / np.sqrt(auto[ref])
        u = source.units[ref] if source.units else ""
        units = (f"{u}/√Hz" if u else "1/√Hz") if source.scaling == "density" else u
        if len(set(source.units)) > 1:
            units = "channel unit" + ("/√Hz" if source.scaling == "density" else "")
        kind, in_name = "csd", None
    else:
        raise TypeError(f"source must be an FRF or a CrossSpectralMatrix, not {type(source).__name__}")
    shape = vals.copy()
    mx = np.nanmax(np.abs(shape)) if shape.size else 0.0
    if shape[ref] != 0 and mx > 0:
        shape = shape * (np.conj(shape[ref]) / abs(shape[ref])) / mx
        shape[ref] = abs(vals[ref]) / mx  # exactly real positive
    return OperatingShape(frequency=float(source.frequencies[k]), shape=shape, points=points, source=kind,
                          reference=points[ref], values=vals, units=units, requested_frequency=float(frequency),
                          input=in_name)
