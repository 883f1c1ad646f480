"""Excitation signals: band-limited random noise, random-phase multisines (full, odd,
random-odd), sine sweeps, impacts and steps, and a parser for CLI specs.

Every generator takes the sampling frequency `fs` (Hz) and the length, as a sample count
`n` or a `duration` in s (``n = round(duration * fs)``), and returns a float array of
shape (n,) in the unit of its amplitude argument (N for force inputs).

References
----------
.. [1] R. Pintelon, J. Schoukens, *System Identification: A Frequency Domain Approach*,
   2nd ed., IEEE Press / Wiley, 2012, ch. 2 (random-phase and random-odd multisines).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy import signal

__all__ = [
    "band_limited_random",
    "multisine",
    "sine_sweep",
    "impact",
    "step",
    "Excitation",
    "parse_excitation",
]


def _n(fs: float, n: int | None, duration: float | None) -> int:
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"{fs=} must be positive")
    if (n is None) == (duration is None):
        raise ValueError(f"give exactly one of n and duration, got {n=}, {duration=}")
    if n is None:
        n = int(round(float(duration) * fs))
    n = int(n)
    if n < 2:
        raise ValueError(f"{n=} must be >= 2 samples")
    return n


def _band(fs: float, n: int, fmin: float, fmax: float) -> np.ndarray:
    if not 0 <= fmin < fmax <= fs / 2:
        raise ValueError(f"need 0 <= fmin < fmax <= fs/2, got {fmin=}, {fmax=}, {fs=}")
    f = np.fft.rfftfreq(n, 1 / fs)
    return np.nonzero((f >= fmin) & (f <= fmax) & (f > 0))[0]


def band_limited_random(
    fs: float,
    n: int | None = None,
    *,
    duration: float | None = None,
    fmin: float = 0.0,
    fmax: float | None = None,
    rms: float = 1.0,
    seed: int | None = None,
) -> np.ndarray:
    """Gaussian noise with a flat spectrum in ``[fmin, fmax]`` Hz and none outside.

    White Gaussian noise is filtered ideally in the frequency domain (DFT bins outside the
    band set to zero) and scaled to the RMS value `rms`.

    Parameters
    ----------
    fs : float
        Sampling frequency in Hz, > 0.
    n : int, optional
        Number of samples, >= 2. Give exactly one of `n` and `duration`.
    duration : float, optional
        Record length in s (``n = round(duration * fs)``), instead of `n`.
    fmin : float, optional
        Lower band edge in Hz; default 0.
    fmax : float, optional
        Upper band edge in Hz; default ``fs / 2``. The 0 Hz line is never excited.
    rms : float, optional
        RMS value of the result, in the unit of the excitation (N for a force); default 1.
    seed : int, optional
        Seed of :func:`numpy.random.default_rng`; default None (not reproducible).

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    ValueError
        If the band is empty or outside ``[0, fs/2]``, or `fs` is not positive, not exactly one of `n` and `duration` is given, or ``n < 2``.
    """
    n = _n(fs, n, duration)
    fmax = fs / 2 if fmax is None else fmax
    idx = _band(fs, n, fmin, fmax)
    if idx.size == 0:
        raise ValueError(f"no DFT line in [{fmin}, {fmax}] Hz for {n=} samples at {fs=} Hz")
    rng = np.random.default_rng(seed)
    X = np.fft.rfft(rng.standard_normal(n))
    mask = np.zeros(X.shape, bool)
    mask[idx] = True
    X[~mask] = 0
    x = np.fft.irfft(X, n)
    return x * (rms / np.sqrt(np.mean(x**2)))


def multisine(
    fs: float,
    n: int | None = None,
    *,
    duration: float | None = None,
    fmin: float = 0.0,
    fmax: float | None = None,
    rms: float = 1.0,
    lines: Literal["all", "odd", "random_odd"] = "all",
    group: int = 3,
    seed: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Random-phase multisine, one period of `n` samples (periodic: frequency resolution ``fs/n``).

    ``x[t] = sum_k A cos(2 pi k t / n + phi_k)`` over the excited DFT lines ``k`` with equal
    amplitudes and phases uniform in ``[0, 2 pi)``, scaled to RMS `rms` [1]_.

    Parameters
    ----------
    fs : float
        Sampling frequency in Hz, > 0.
    n : int, optional
        Number of samples, >= 2. Give exactly one of `n` and `duration`.
    duration : float, optional
        Record length in s (``n = round(duration * fs)``), instead of `n`.
    fmin : float, optional
        Lower edge of the excited band in Hz; default 0.
    fmax : float, optional
        Upper edge in Hz; default ``fs / 2``. The 0 Hz and Nyquist lines are never excited.
    rms : float, optional
        RMS value of the result (N for a force); default 1.
    lines : {"all", "odd", "random_odd"}
        ``"all"``: every line in ``[fmin, fmax]``; ``"odd"``: odd lines only (even
        nonlinearities fall on the even lines); ``"random_odd"``: odd lines with one line
        removed at random in each group of `group` consecutive odd lines (detection lines
        for odd nonlinear distortions).
    group : int
        Group size for ``"random_odd"``; default 3.
    seed : int, optional
        Seed of :func:`numpy.random.default_rng` (phases, and the removed lines of
        ``"random_odd"``); default None (not reproducible).

    Returns
    -------
    x : ndarray, shape (n,)
    excited : ndarray of int
        Excited DFT line indices ``k`` (frequency ``k fs / n``).

    Raises
    ------
    ValueError
        If the band is outside ``[0, fs/2]`` or excites no line, `lines` is unknown, or
        `fs` is not positive, not exactly one of `n` and `duration` is given, or ``n < 2``.
    """
    n = _n(fs, n, duration)
    fmax = fs / 2 if fmax is None else fmax
    k = _band(fs, n, fmin, fmax)
    k = k[k < n / 2]  # no Nyquist line
    rng = np.random.default_rng(seed)
    if lines == "odd":
        k = k[k % 2 == 1]
    elif lines == "random_odd":
        k = k[k % 2 == 1]
        keep = np.ones(k.size, bool)
        for start in range(0, k.size - group + 1, group):
            keep[start + rng.integers(group)] = False
        k = k[keep]
    elif lines != "all":
        raise ValueError(f"{lines=} must be 'all', 'odd' or 'random_odd'")
    if k.size == 0:
        raise ValueError(f"no excited line in [{fmin}, {fmax}] Hz for {n=} samples at {fs=} Hz")
    X = np.zeros(n // 2 + 1, complex)
    X[k] = np.exp(2j * np.pi * rng.random(k.size))
    x = np.fft.irfft(X, n)
    return x * (rms / np.sqrt(np.mean(x**2))), k


def sine_sweep(
    fs: float,
    n: int | None = None,
    *,
    duration: float | None = None,
    f0: float = 1.0,
    f1: float | None = None,
    amplitude: float = 1.0,
    kind: Literal["linear", "log"] = "linear",
    seed: int | None = None,
) -> np.ndarray:
    """Swept sine ``amplitude sin(phi(t))`` from `f0` to `f1` Hz over the record, linear or
    logarithmic (exponential) in frequency, starting at phase 0 (``x[0] = 0``).

    `seed` is accepted for a uniform signature and unused.

    Parameters
    ----------
    fs : float
        Sampling frequency in Hz, > 0.
    n : int, optional
        Number of samples, >= 2. Give exactly one of `n` and `duration`.
    duration : float, optional
        Record length in s (``n = round(duration * fs)``), instead of `n`.
    f0 : float, optional
        Start frequency in Hz, at ``t = 0``; default 1.
    f1 : float, optional
        End frequency in Hz, reached at the last sample; default ``fs / 2``. May be below `f0`
        (a downward sweep).
    amplitude : float, optional
        Peak value (N for a force); default 1.
    kind : {"linear", "log"}, optional
        Frequency law in time; default ``"linear"``.
    seed : int, optional
        Unused.

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    ValueError
        If `f0` or `f1` is not in ``(0, fs/2]``, `kind` is unknown, or `fs` is not positive, not exactly one of `n` and `duration` is given, or ``n < 2``.
    """
    n = _n(fs, n, duration)
    f1 = fs / 2 if f1 is None else f1
    if f0 <= 0 or f1 <= 0 or max(f0, f1) > fs / 2:
        raise ValueError(f"need 0 < f0, f1 <= fs/2, got {f0=}, {f1=}, {fs=}")
    if kind not in ("linear", "log"):
        raise ValueError(f"{kind=} must be 'linear' or 'log'")
    t = np.arange(n) / fs
    T = (n - 1) / fs
    return amplitude * signal.chirp(t, f0, T, f1, method="linear" if kind == "linear" else "logarithmic", phi=-90)


def impact(
    fs: float,
    n: int | None = None,
    *,
    duration: float | None = None,
    peak: float = 1.0,
    pulse: float = 0.002,
    t_start: float = 0.0,
    seed: int | None = None,
) -> np.ndarray:
    """Half-sine force pulse of height `peak` and length `pulse` s starting at `t_start` s
    (an idealised hammer impact; its spectrum is flat to about ``1 / (2 pulse)`` Hz).

    Parameters
    ----------
    fs : float
        Sampling frequency in Hz, > 0.
    n : int, optional
        Number of samples, >= 2. Give exactly one of `n` and `duration`.
    duration : float, optional
        Record length in s (``n = round(duration * fs)``), instead of `n`.
    peak : float, optional
        Pulse height (N for a force); default 1.
    pulse : float, optional
        Pulse length in s, > 0; default 0.002.
    t_start : float, optional
        Start of the pulse in s from the first sample; default 0.
    seed : int, optional
        Unused (uniform signature).

    Returns
    -------
    ndarray, shape (n,)
        Zero outside ``[t_start, t_start + pulse]``.

    Raises
    ------
    ValueError
        If `pulse` is not positive, or `fs` is not positive, not exactly one of `n` and `duration` is given, or ``n < 2``.
    """
    n = _n(fs, n, duration)
    if pulse <= 0:
        raise ValueError(f"{pulse=} must be > 0 s")
    t = np.arange(n) / fs - t_start
    x = np.where((t >= 0) & (t <= pulse), peak * np.sin(np.pi * np.clip(t, 0, pulse) / pulse), 0.0)
    return x


def step(
    fs: float,
    n: int | None = None,
    *,
    duration: float | None = None,
    amplitude: float = 1.0,
    t_start: float = 0.0,
    seed: int | None = None,
) -> np.ndarray:
    """Step of height `amplitude` at `t_start` s (0 before).

    Parameters
    ----------
    fs : float
        Sampling frequency in Hz, > 0.
    n : int, optional
        Number of samples, >= 2. Give exactly one of `n` and `duration`.
    duration : float, optional
        Record length in s (``n = round(duration * fs)``), instead of `n`.
    amplitude : float, optional
        Step height (N for a force); default 1.
    t_start : float, optional
        Time of the step in s from the first sample; default 0.
    seed : int, optional
        Unused (uniform signature).

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    ValueError
        If `fs` is not positive, not exactly one of `n` and `duration` is given, or ``n < 2``.
    """
    n = _n(fs, n, duration)
    t = np.arange(n) / fs
    return np.where(t >= t_start, float(amplitude), 0.0)


_KINDS = {
    "random": (band_limited_random, {"fmin", "fmax", "rms"}),
    "multisine": (multisine, {"fmin", "fmax", "rms", "lines", "group"}),
    "sweep": (sine_sweep, {"f0", "f1", "amplitude", "kind"}),
    "impact": (impact, {"peak", "duration", "pulse", "t_start"}),
    "step": (step, {"amplitude", "t_start"}),
}


#: Older spec keys still read (the README's ``random:f_lo=1,f_hi=150,rms=10``): the band edges
#: are ``fmin``/``fmax`` everywhere else (the CLI's ``--fmin``/``--fmax``, the estimators).
_KEY_ALIASES = {"f_lo": "fmin", "f_hi": "fmax"}


@dataclass(frozen=True)
class Excitation:
    """A parsed excitation spec: `kind` and its keyword `params`; call :meth:`generate`.

    Parameters
    ----------
    kind : {"random", "multisine", "sweep", "impact", "step"}
        The generator: :func:`band_limited_random`, :func:`multisine`, :func:`sine_sweep`,
        :func:`impact` or :func:`step`. Not checked here (see :func:`parse_excitation`).
    params : dict, optional
        Keyword arguments of that generator (for ``impact``, the key ``duration`` is the
        pulse length in s); default empty.
    """

    kind: str
    params: dict = field(default_factory=dict)

    def generate(self, fs: float, n: int, seed: int | None = None) -> np.ndarray:
        """The excitation, shape (n,), at `fs` Hz (multisines: periodic in `n`).

        Parameters
        ----------
        fs : float
            Sampling frequency in Hz.
        n : int
            Number of samples.
        seed : int, optional
            Seed passed to the generator (used by ``random`` and ``multisine``); default None.

        Returns
        -------
        ndarray, shape (n,)
            For a multisine, the signal only (not the excited lines).

        Raises
        ------
        KeyError
            If :attr:`kind` is not a known kind.
        ValueError
            As the generator.
        """
        func, _ = _KINDS[self.kind]
        params = dict(self.params)
        if self.kind == "impact" and "duration" in params:  # pulse length, not record length
            params["pulse"] = params.pop("duration")
        out = func(fs, n, seed=seed, **params)
        return out[0] if isinstance(out, tuple) else out


def parse_excitation(spec: str) -> Excitation:
    """Parse a CLI excitation spec ``KIND:key=value,key=value``.

    Kinds and keys (``f_lo``, ``f_hi`` are read as ``fmin``, ``fmax``): ``random`` (fmin, fmax,
    rms), ``multisine`` (fmin, fmax, rms,
    lines=all|odd|random_odd, group), ``sweep`` (f0, f1, amplitude, kind=linear|log),
    ``impact`` (peak, duration = pulse length in s, t_start), ``step`` (amplitude, t_start).

    Parameters
    ----------
    spec : str
        The spec, e.g. ``"sweep:f0=1,f1=200,amplitude=5"``. Values are floats (Hz, s, or the
        excitation's unit), but ``group`` is an int and ``lines``, ``kind`` are strings.

    Returns
    -------
    Excitation

    Raises
    ------
    ValueError
        For an unknown kind or key, or a malformed value.

    Examples
    --------
    >>> parse_excitation("random:fmin=1,fmax=200,rms=10")
    Excitation(kind='random', params={'fmin': 1.0, 'fmax': 200.0, 'rms': 10.0})
    >>> parse_excitation("random:f_lo=1,f_hi=200,rms=10") == parse_excitation("random:fmin=1,fmax=200,rms=10")
    True
    """
    kind, _, rest = spec.strip().partition(":")
    kind = kind.strip()
    if kind not in _KINDS:
        raise ValueError(f"unknown excitation {kind=} in {spec=}; known: {sorted(_KINDS)}")
    allowed = _KINDS[kind][1]
    params: dict = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, val = item.partition("=")
        key = key.strip()
        if key not in allowed and _KEY_ALIASES.get(key) in allowed:
            key = _KEY_ALIASES[key]
        if not eq:
            raise ValueError(f"expected key=value, got {item!r} in {spec=}")
        if key not in allowed:
            raise ValueError(f"unknown key {key!r} for excitation {kind!r}; known: {sorted(allowed)}")
        val = val.strip()
        if key in ("lines", "kind"):
            params[key] = val
        elif key == "group":
            params[key] = int(val)
        else:
            try:
                params[key] = float(val)
            except ValueError:
                raise ValueError(f"{key}={val!r} is not a number in {spec=}") from None
    return Excitation(kind, params)
