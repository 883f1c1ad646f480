"""Frequency and step responses of SISO LTI systems through python-control.

The small result objects :class:`BodeResult`, :class:`NyquistResult` and
:class:`StepResult` are frozen dataclasses carrying their axes; their ``.plot()`` draws
through :mod:`vibroscope.viewers.instruments` (matplotlib imported on first use).

The numbers come from python-control: :func:`control.frequency_response` for the Bode and
Nyquist data, :func:`control.forced_response` for the step and :func:`control.step_info`
for the settling time, overshoot and peak.  Only the rise time is refined here: python-control
reports the first *sample* at or above each level, we interpolate linearly between that
sample and the one before, so the criterion varies smoothly with the system's parameters
(the influence coefficients of :mod:`vibroscope.instruments.influence` difference it).

References
----------
.. [1] R. M. Murray et al., python-control, ``control.frequency_response``,
   ``control.step_info``, https://python-control.readthedocs.io
.. [2] K. Ogata, *Modern Control Engineering*, 5th ed., Prentice Hall, 2010, ch. 5
   (rise time, settling time, overshoot definitions).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import control
import numpy as np

from vibroscope._checks import read_only

__all__ = [
    "BodeResult",
    "NyquistResult",
    "StepResult",
    "bode",
    "nyquist",
    "step_response",
    "step_info",
    "clean_tf",
]


def _ro(a) -> np.ndarray:
    """Read-only float (or complex) copy (:func:`vibroscope._checks.read_only`)."""
    return read_only(a, complex if np.iscomplexobj(a) else float)


def _num_den(tf: control.TransferFunction) -> tuple[np.ndarray, np.ndarray]:
    return (np.atleast_1d(np.squeeze(tf.num[0][0])).astype(float),
            np.atleast_1d(np.squeeze(tf.den[0][0])).astype(float))


def clean_tf(sys, tol: float = 1e-10) -> control.TransferFunction:
    """SISO transfer function with cancelled pole/zero pairs and negligible coefficients removed.

    Parameters
    ----------
    sys : control.LTI
        A SISO system (``StateSpace`` or ``TransferFunction``).
    tol : float
        Relative tolerance: numerator coefficients smaller than ``tol`` times the largest
        one are set to zero; ``control.minreal`` is run with the same tolerance.

    Returns
    -------
    control.TransferFunction
        With a monic denominator.  Where ``control.minreal`` cannot reduce the system
        (a ``ValueError`` or ``LinAlgError`` of an ill-conditioned pole/zero set), it is
        returned unreduced.
    """
    tf = control.tf(sys)
    if tf.ninputs != 1 or tf.noutputs != 1:
        raise ValueError(f"clean_tf needs a SISO system, got {tf.ninputs=} {tf.noutputs=}")
    num, den = _num_den(tf)
    scale = max(np.max(np.abs(num)), 1e-300)
    num = np.where(np.abs(num) < tol * scale, 0.0, num)
    num = np.trim_zeros(num, "f")
    if num.size == 0:
        return control.tf([0.0], [1.0])
    tf = control.tf(num, den)
    try:
        tf = control.minreal(tf, tol=np.sqrt(tol), verbose=False)
    except (ValueError, np.linalg.LinAlgError):  # best effort: keep the unreduced system
        pass
    num, den = _num_den(tf)
    return control.tf(num / den[0], den / den[0])


# --------------------------------------------------------------------------- results


@dataclass(frozen=True, eq=False)
class BodeResult:
    """Frequency response as magnitude (linear, output unit per input unit) and phase.

    Attributes
    ----------
    frequencies : ndarray
        Frequencies in Hz.
    magnitude : ndarray
        |G(j 2 pi f)|, linear.
    phase_deg : ndarray
        Unwrapped phase in degrees.
    """

    frequencies: np.ndarray
    magnitude: np.ndarray
    phase_deg: np.ndarray

    def __iter__(self):
        return iter((self.frequencies, self.magnitude, self.phase_deg))

    @property
    def magnitude_db(self) -> np.ndarray:
        return 20.0 * np.log10(np.maximum(self.magnitude, 1e-300))

    def plot(self, axes=None, label: str | None = None, **kwargs):
        """Magnitude (dB) and phase (deg) on log frequency axes; returns the two axes
        (:func:`vibroscope.viewers.instruments.plot_bode`).

        Parameters
        ----------
        axes : sequence of 2 matplotlib.axes.Axes, optional
            Magnitude and phase axes to draw on; default a new figure.
        label : str, optional
            Legend label of the curves.
        **kwargs
            Passed to ``Axes.semilogx``.

        Returns
        -------
        (Axes, Axes)
        """
        from vibroscope._plotting import draw

        return draw("plot_bode", self, axes, label=label, **kwargs)


@dataclass(frozen=True, eq=False)
class NyquistResult:
    """Nyquist locus ``G(j 2 pi f)`` for positive frequencies.

    Attributes
    ----------
    frequencies : ndarray
        Frequencies in Hz.
    response : ndarray of complex
        Complex frequency response.
    """

    frequencies: np.ndarray
    response: np.ndarray

    def __iter__(self):
        return iter((self.frequencies, self.response))

    def plot(self, ax=None, label: str | None = None, mirror: bool = True, **kwargs):
        """Re/Im locus (with its mirror image for negative frequencies, dashed)
        (:func:`vibroscope.viewers.instruments.plot_nyquist`).

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes to draw on; default a new figure.
        label : str, optional
            Legend label of the locus.
        mirror : bool, optional
            Also draw the mirror image (negative frequencies), dashed; default True.
        **kwargs
            Passed to ``Axes.plot`` for the locus.

        Returns
        -------
        matplotlib.axes.Axes
        """
        from vibroscope._plotting import draw

        return draw("plot_nyquist", self, ax, label=label, mirror=mirror, **kwargs)


@dataclass(frozen=True, eq=False, kw_only=True)
class StepResult:
    """Step response with its standard time-domain criteria.

    Attributes
    ----------
    time_s : ndarray
        Time in s.
    response : ndarray
        Response to a step of height `amplitude` (output unit).
    rise_time_s : float
        10 %-90 % rise time of the step response toward its final value, in s (nan if the
        response does not settle or has zero final value).
    settling_time_s : float
        Time after which the response stays within 2 % of its final value, in s.
    overshoot_pct : float
        Peak overshoot beyond the final value, in % of the final value.
    peak : float
        Largest absolute value of the response.
    final_value : float
        Final value from the DC gain (times the step amplitude); inf for a type >= 1 plant.
    """

    time_s: np.ndarray
    response: np.ndarray
    rise_time_s: float
    settling_time_s: float
    overshoot_pct: float
    peak: float
    final_value: float = float("nan")

    def __iter__(self):
        return iter((self.time_s, self.response))

    def plot(self, ax=None, label: str | None = None, **kwargs):
        """Response versus time; returns the axes (:func:`vibroscope.viewers.instruments.plot_step`).

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes to draw on; default a new figure.
        label : str, optional
            Legend label of the curve.
        **kwargs
            Passed to ``Axes.plot``.

        Returns
        -------
        matplotlib.axes.Axes
        """
        from vibroscope._plotting import draw

        return draw("plot_step", self, ax, label=label, **kwargs)


# --------------------------------------------------------------------------- functions


def _freq_response(sys, frequencies) -> np.ndarray:
    """Complex response of a SISO system at `frequencies`, by :func:`control.frequency_response`."""
    f = np.asarray(frequencies, dtype=float)
    if f.ndim != 1 or f.size == 0 or np.any(f < 0):
        raise ValueError(f"frequencies must be a 1-D array of non-negative Hz, got shape {f.shape}")
    tf = control.tf(sys)
    if tf.ninputs != 1 or tf.noutputs != 1:
        raise ValueError("only SISO systems are supported")
    with warnings.catch_warnings():  # a pole at f = 0 gives inf, by design
        warnings.filterwarnings("ignore", "divide by zero", RuntimeWarning)
        warnings.filterwarnings("ignore", "invalid value", RuntimeWarning)
        return np.asarray(control.frequency_response(tf, 2.0 * np.pi * f).complex).reshape(-1)


def bode(sys, frequencies) -> BodeResult:
    """Bode magnitude and phase of a SISO LTI system.

    Parameters
    ----------
    sys : control.LTI
        SISO system (time unit s).
    frequencies : array_like
        Frequencies in Hz.

    Returns
    -------
    BodeResult
        Linear magnitude and unwrapped phase in degrees.

    Examples
    --------
    >>> import control, numpy as np
    >>> r = bode(control.tf([1], [1 / (2 * np.pi), 1]), [1.0])   # first order, corner 1 Hz
    >>> round(float(r.magnitude[0]), 4), round(float(r.phase_deg[0]), 1)
    (0.7071, -45.0)
    """
    f = np.asarray(frequencies, dtype=float)
    h = _freq_response(sys, f)
    return BodeResult(_ro(f), _ro(np.abs(h)), _ro(np.degrees(np.unwrap(np.angle(h)))))


def nyquist(sys, frequencies) -> NyquistResult:
    """Nyquist locus (complex frequency response) of a SISO LTI system.

    Parameters
    ----------
    sys : control.LTI
        SISO system (time unit s).
    frequencies : array_like
        Frequencies in Hz.

    Returns
    -------
    NyquistResult
        The complex response at `frequencies`.
    """
    f = np.asarray(frequencies, dtype=float)
    h = _freq_response(sys, f)
    return NyquistResult(_ro(f), _ro(h))


def _crossing_time(t: np.ndarray, yn: np.ndarray, level: float) -> float:
    """First time the normalised response reaches `level`, linearly interpolated between samples."""
    idx = np.flatnonzero(yn >= level)
    if idx.size == 0:
        return np.nan
    k = idx[0]
    if k == 0:
        return float(t[0])
    return float(t[k - 1] + (level - yn[k - 1]) * (t[k] - t[k - 1]) / (yn[k] - yn[k - 1]))


def step_info(t, y, final_value: float | None = None, settling_band: float = 0.02) -> dict:
    """Rise time (10-90 %), settling time (2 %), overshoot (%) and peak of a step response.

    Settling time, overshoot and peak are :func:`control.step_info`'s; the rise time is
    interpolated between samples (see the module notes).

    Parameters
    ----------
    t, y : array_like
        Time (s) and response samples.
    final_value : float, optional
        Final value; the last sample by default.
    settling_band : float
        Relative band for the settling time (0.02 = 2 %).

    Returns
    -------
    dict
        Keys ``rise_time_s``, ``settling_time_s``, ``overshoot_pct``, ``peak``; nan criteria
        (but the peak) for a zero or non-finite final value, nan rise and settling times for
        a response that never reaches 90 % of its final value.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    yf = float(y[-1]) if final_value is None else float(final_value)
    peak = float(np.max(np.abs(y)))
    if not np.isfinite(yf) or yf == 0.0:
        return dict(rise_time_s=np.nan, settling_time_s=np.nan, overshoot_pct=np.nan, peak=peak)
    yn = y / yf
    rise = _crossing_time(t, yn, 0.9) - _crossing_time(t, yn, 0.1)
    if not np.isfinite(rise):  # never reaches 90 %: control.step_info would fail to index
        return dict(rise_time_s=np.nan, settling_time_s=np.nan, overshoot_pct=0.0, peak=peak)
    info = control.step_info(y, T=t, yfinal=yf, SettlingTimeThreshold=settling_band)
    return dict(rise_time_s=float(rise), settling_time_s=float(info["SettlingTime"]),
                overshoot_pct=float(info["Overshoot"]), peak=float(info["Peak"]))


def step_response(sys, t, amplitude: float = 1.0) -> StepResult:
    """Step response of a SISO LTI system on the time grid `t` (s), with its criteria.

    Parameters
    ----------
    sys : control.LTI
        SISO system.
    t : array_like
        Increasing time grid in s, starting at 0.
    amplitude : float
        Height of the input step (input unit).

    Returns
    -------
    StepResult
        Criteria are computed against the DC-gain final value (or the last sample for a
        system with an integrator, for which ``final_value`` is inf).

    Examples
    --------
    >>> import control, numpy as np
    >>> r = step_response(control.tf([1], [1, 1]), np.linspace(0, 10, 10001))
    >>> round(r.rise_time_s, 3)    # ln 9 for a first-order lag of 1 s
    2.197
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0):
        raise ValueError("t must be a 1-D increasing time grid in s")
    tf = control.tf(sys)
    resp = control.forced_response(tf, T=t, U=np.full(t.size, float(amplitude)))
    y = np.asarray(resp.outputs, dtype=float).reshape(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        dc = float(np.real(control.dcgain(tf)))
    fv = dc * amplitude if np.isfinite(dc) else np.inf
    info = step_info(t, y, final_value=fv if np.isfinite(fv) else None)
    if not np.isfinite(fv):
        info = dict(info, rise_time_s=np.nan, settling_time_s=np.nan, overshoot_pct=np.nan)
    return StepResult(time_s=_ro(t), response=_ro(y), rise_time_s=info["rise_time_s"],
                      settling_time_s=info["settling_time_s"], overshoot_pct=info["overshoot_pct"],
                      peak=info["peak"], final_value=fv)
