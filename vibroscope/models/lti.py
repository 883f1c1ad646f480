"""LTI models and block schemas through python-control.

A :class:`BlockSchema` is a signal graph: named blocks (``control.TransferFunction`` or
``control.StateSpace``), each reading one named signal and writing another, plus summing
junctions.  From it we obtain the transfer function from any exogenous input (reference,
load disturbance) to *every* named signal of the schema, which is what the founding
paper's "indicial characteristics in all points of the block schema" instrument shows.

The small result objects :class:`BodeResult`, :class:`NyquistResult` and
:class:`StepResult` are frozen dataclasses carrying their axes and a lazy ``.plot()``.

References
----------
.. [1] A. Olaru and S. Olaru, "Assisted dynamic behavior optimization with LabVIEW
   instrumentation", Proc. CSIT vol. 1, IACSIT Press, Singapore, 2011.
.. [2] R. M. Murray et al., python-control, ``control.interconnect``,
   https://python-control.readthedocs.io
.. [3] K. Ogata, *Modern Control Engineering*, 5th ed., Prentice Hall, 2010, ch. 5
   (rise time, settling time, overshoot definitions).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import control
import numpy as np

__all__ = [
    "Block",
    "Sum",
    "BlockSchema",
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
    a = np.array(a, dtype=float if not np.iscomplexobj(a) else complex)
    a.flags.writeable = False
    return a


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
    """
    tf = control.tf(sys)
    if tf.ninputs != 1 or tf.noutputs != 1:
        raise ValueError(f"clean_tf needs a SISO system, got {tf.ninputs=} {tf.noutputs=}")
    num = np.atleast_1d(np.squeeze(tf.num[0][0])).astype(float)
    den = np.atleast_1d(np.squeeze(tf.den[0][0])).astype(float)
    scale = max(np.max(np.abs(num)), 1e-300)
    num = np.where(np.abs(num) < tol * scale, 0.0, num)
    num = np.trim_zeros(num, "f")
    if num.size == 0:
        return control.tf([0.0], [1.0])
    tf = control.tf(num, den)
    try:
        tf = control.minreal(tf, tol=np.sqrt(tol), verbose=False)
    except Exception:  # pragma: no cover - minreal is best-effort
        pass
    num = np.atleast_1d(np.squeeze(tf.num[0][0])).astype(float)
    den = np.atleast_1d(np.squeeze(tf.den[0][0])).astype(float)
    # normalise to monic denominator
    return control.tf(num / den[0], den / den[0])


# --------------------------------------------------------------------------- schema


@dataclass(frozen=True)
class Block:
    """One LTI block of a schema: ``output = sys * input``.

    Parameters
    ----------
    name : str
        Block name (e.g. ``"regulator"``).
    sys : control.TransferFunction or control.StateSpace
        SISO LTI model of the block.
    input : str
        Name of the signal the block reads.
    output : str
        Name of the signal the block writes (a "named point" of the schema).
    """

    name: str
    sys: object
    input: str
    output: str


@dataclass(frozen=True)
class Sum:
    """A summing junction: ``output = sum(sign * signal)``.

    Parameters
    ----------
    output : str
        Name of the signal written.
    inputs : tuple of str
        Signal names, each optionally prefixed with ``"-"`` for subtraction
        (``("r", "-y")`` is the error of a unity-feedback loop).
    """

    output: str
    inputs: tuple[str, ...]


@dataclass(frozen=True)
class BlockSchema:
    """A block diagram of named SISO LTI blocks and summing junctions.

    Parameters
    ----------
    blocks : tuple of Block
        The dynamic blocks.
    sums : tuple of Sum, optional
        Summing junctions.
    inputs : tuple of str, optional
        Exogenous signals (reference ``"r"``, load disturbance ``"d"``...).  Defaults to
        ``("r",)``.
    name : str, optional
        A title for plots.

    Notes
    -----
    The closed system is built once with :func:`control.interconnect`, using signal names
    for the connections; :meth:`transfer` then returns the SISO transfer function from an
    exogenous input to any named signal.  Series, parallel and feedback arrangements are
    simply particular graphs; :meth:`series`, :meth:`parallel` and :meth:`feedback` build
    them.

    Examples
    --------
    >>> import control
    >>> g = control.tf([1], [1, 1])
    >>> loop = BlockSchema.feedback(g, control.tf([1], [1]))
    >>> round(float(control.dcgain(loop.transfer("y"))), 6)
    0.5
    """

    blocks: tuple[Block, ...]
    sums: tuple[Sum, ...] = ()
    inputs: tuple[str, ...] = ("r",)
    name: str = ""
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "blocks", tuple(self.blocks))
        object.__setattr__(self, "sums", tuple(self.sums))
        object.__setattr__(self, "inputs", tuple(self.inputs))
        outs = [b.output for b in self.blocks] + [s.output for s in self.sums]
        if len(set(outs)) != len(outs):
            raise ValueError(f"each signal must be written once, got outputs {outs=}")
        bad = set(outs) & set(self.inputs)
        if bad:
            raise ValueError(f"exogenous inputs {sorted(bad)} are also written by a block or sum")
        known = set(outs) | set(self.inputs)
        for b in self.blocks:
            if b.input not in known:
                raise ValueError(f"block {b.name!r} reads unknown signal {b.input!r}")
        for s in self.sums:
            for sig in s.inputs:
                if sig.lstrip("-+") not in known:
                    raise ValueError(f"sum {s.output!r} reads unknown signal {sig!r}")

    # ---------------------------------------------------------------- builders
    @classmethod
    def series(cls, *systems, names: Sequence[str] | None = None, name: str = "") -> "BlockSchema":
        """Blocks in series ``r -> G1 -> x1 -> G2 -> ... -> y``; the last signal is ``"y"``."""
        names = list(names) if names is not None else [f"G{i + 1}" for i in range(len(systems))]
        blocks, prev = [], "r"
        for i, (n, g) in enumerate(zip(names, systems)):
            out = "y" if i == len(systems) - 1 else f"x{i + 1}"
            blocks.append(Block(n, g, prev, out))
            prev = out
        return cls(tuple(blocks), (), ("r",), name)

    @classmethod
    def parallel(cls, *systems, names: Sequence[str] | None = None, name: str = "") -> "BlockSchema":
        """Blocks in parallel, each fed by ``"r"``, outputs ``x1..xn`` summed into ``"y"``."""
        names = list(names) if names is not None else [f"G{i + 1}" for i in range(len(systems))]
        blocks = tuple(Block(n, g, "r", f"x{i + 1}") for i, (n, g) in enumerate(zip(names, systems)))
        return cls(blocks, (Sum("y", tuple(b.output for b in blocks)),), ("r",), name)

    @classmethod
    def feedback(cls, forward, back=None, *, sign: int = -1, name: str = "") -> "BlockSchema":
        """Feedback loop ``e = r + sign*m``, ``y = forward*e``, ``m = back*y`` (unity if None)."""
        back = control.tf([1.0], [1.0]) if back is None else back
        s = "-m" if sign < 0 else "m"
        return cls(
            (Block("forward", forward, "e", "y"), Block("feedback", back, "y", "m")),
            (Sum("e", ("r", s)),),
            ("r",),
            name,
        )

    # ---------------------------------------------------------------- analysis
    @property
    def signals(self) -> tuple[str, ...]:
        """Every named point: exogenous inputs first, then sums and block outputs in order."""
        return self.inputs + tuple(s.output for s in self.sums) + tuple(b.output for b in self.blocks)

    @property
    def internal_signals(self) -> tuple[str, ...]:
        return tuple(s.output for s in self.sums) + tuple(b.output for b in self.blocks)

    def system(self) -> control.StateSpace:
        """The interconnected MIMO state-space system (inputs ``self.inputs``, outputs every internal signal)."""
        if "sys" not in self._cache:
            syslist = []
            for b in self.blocks:
                g = b.sys
                if isinstance(g, control.TransferFunction):
                    g = control.tf(g.num, g.den, inputs=b.input, outputs=b.output, name=b.name)
                else:
                    g = control.ss(g, inputs=b.input, outputs=b.output, name=b.name)
                syslist.append(g)
            for k, s in enumerate(self.sums):
                ins = [sig[1:] if sig.startswith("+") else sig for sig in s.inputs]
                syslist.append(control.summing_junction(inputs=ins, output=s.output, name=f"sum{k}_{s.output}"))
            self._cache["sys"] = control.interconnect(
                syslist, inplist=list(self.inputs), outlist=list(self.internal_signals), check_unused=False
            )
        return self._cache["sys"]

    def transfer(self, to: str, from_: str | None = None) -> control.TransferFunction:
        """SISO transfer function from exogenous input `from_` (default: the first) to signal `to`.

        Parameters
        ----------
        to : str
            A named point of the schema (see :attr:`signals`).
        from_ : str, optional
            An exogenous input; defaults to ``self.inputs[0]`` (the reference).

        Returns
        -------
        control.TransferFunction
            Cleaned (minimal, monic denominator) transfer function.
        """
        from_ = self.inputs[0] if from_ is None else from_
        if from_ not in self.inputs:
            raise ValueError(f"{from_=} is not an exogenous input of the schema {self.inputs=}")
        if to not in self.signals:
            raise ValueError(f"{to=} is not a signal of the schema {self.signals=}")
        if to in self.inputs:
            return control.tf([1.0 if to == from_ else 0.0], [1.0])
        key = ("tf", to, from_)
        if key not in self._cache:
            sys = self.system()
            i = self.inputs.index(from_)
            o = self.internal_signals.index(to)
            self._cache[key] = clean_tf(sys[o, i])
        return self._cache[key]

    def transfers(self, from_: str | None = None) -> dict[str, control.TransferFunction]:
        """Transfer functions from `from_` to every named point, as a dict keyed by signal name."""
        return {s: self.transfer(s, from_) for s in self.signals}

    def step(self, t, from_: str | None = None, amplitude: float = 1.0) -> dict[str, "StepResult"]:
        """Indicial (step) responses at every named point to a step of `from_`.

        Parameters
        ----------
        t : array_like
            Time grid in s.
        from_ : str, optional
            Exogenous input stepped (default: the reference).
        amplitude : float
            Step height, in the unit of that input.
        """
        return {s: step_response(g, t, amplitude=amplitude) for s, g in self.transfers(from_).items()}

    def block_bode(self, frequencies_hz) -> dict[str, "BodeResult"]:
        """Bode data of each block on its own, keyed by block name."""
        return {b.name: bode(b.sys, frequencies_hz) for b in self.blocks}


# --------------------------------------------------------------------------- results


@dataclass(frozen=True, eq=False)
class BodeResult:
    """Frequency response as magnitude (linear, output unit per input unit) and phase.

    Attributes
    ----------
    frequencies_hz : ndarray
        Frequencies in Hz.
    magnitude : ndarray
        |G(j 2 pi f)|, linear.
    phase_deg : ndarray
        Unwrapped phase in degrees.
    """

    frequencies_hz: np.ndarray
    magnitude: np.ndarray
    phase_deg: np.ndarray

    def __iter__(self):
        return iter((self.frequencies_hz, self.magnitude, self.phase_deg))

    @property
    def magnitude_db(self) -> np.ndarray:
        return 20.0 * np.log10(np.maximum(self.magnitude, 1e-300))

    def plot(self, axes=None, label: str | None = None, **kwargs):
        """Magnitude (dB) and phase (deg) on log frequency axes; returns the two axes."""
        import matplotlib.pyplot as plt

        if axes is None:
            _, axes = plt.subplots(2, 1, sharex=True, figsize=(6, 5))
        a1, a2 = axes
        a1.semilogx(self.frequencies_hz, self.magnitude_db, label=label, **kwargs)
        a2.semilogx(self.frequencies_hz, self.phase_deg, label=label, **kwargs)
        a1.set_ylabel("magnitude [dB]")
        a2.set_ylabel("phase [deg]")
        a2.set_xlabel("frequency [Hz]")
        for a in axes:
            a.grid(True, which="both", alpha=0.3)
        return axes


@dataclass(frozen=True, eq=False)
class NyquistResult:
    """Nyquist locus ``G(j 2 pi f)`` for positive frequencies.

    Attributes
    ----------
    frequencies_hz : ndarray
        Frequencies in Hz.
    response : ndarray of complex
        Complex frequency response.
    """

    frequencies_hz: np.ndarray
    response: np.ndarray

    def __iter__(self):
        return iter((self.frequencies_hz, self.response))

    def plot(self, ax=None, label: str | None = None, mirror: bool = True, **kwargs):
        """Re/Im locus (with its mirror image for negative frequencies, dashed)."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(5, 5))
        (line,) = ax.plot(self.response.real, self.response.imag, label=label, **kwargs)
        if mirror:
            ax.plot(self.response.real, -self.response.imag, "--", color=line.get_color(), lw=0.8)
        ax.plot([-1], [0], "r+", ms=10)
        ax.set_xlabel("Re G")
        ax.set_ylabel("Im G")
        ax.grid(True, alpha=0.3)
        return ax


@dataclass(frozen=True, eq=False)
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
        """Response versus time; returns the axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(6, 3.5))
        ax.plot(self.time_s, self.response, label=label, **kwargs)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("response")
        ax.grid(True, alpha=0.3)
        return ax


# --------------------------------------------------------------------------- functions


def _freq_response(sys, frequencies_hz) -> np.ndarray:
    f = np.asarray(frequencies_hz, dtype=float)
    if f.ndim != 1 or f.size == 0 or np.any(f < 0):
        raise ValueError(f"frequencies_hz must be a 1-D array of non-negative Hz, got shape {f.shape}")
    tf = control.tf(sys)
    if tf.ninputs != 1 or tf.noutputs != 1:
        raise ValueError("only SISO systems are supported")
    s = 2j * np.pi * f
    num = np.atleast_1d(np.squeeze(tf.num[0][0]))
    den = np.atleast_1d(np.squeeze(tf.den[0][0]))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.polyval(num, s) / np.polyval(den, s)


def bode(sys, frequencies_hz) -> BodeResult:
    """Bode magnitude and phase of a SISO LTI system.

    Parameters
    ----------
    sys : control.LTI
        SISO system (time unit s).
    frequencies_hz : array_like
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
    f = np.asarray(frequencies_hz, dtype=float)
    h = _freq_response(sys, f)
    return BodeResult(_ro(f), _ro(np.abs(h)), _ro(np.degrees(np.unwrap(np.angle(h)))))


def nyquist(sys, frequencies_hz) -> NyquistResult:
    """Nyquist locus (complex frequency response) of a SISO LTI system at `frequencies_hz` (Hz)."""
    f = np.asarray(frequencies_hz, dtype=float)
    h = _freq_response(sys, f)
    return NyquistResult(_ro(f), _ro(h))


def step_info(t, y, final_value: float | None = None, settling_band: float = 0.02) -> dict:
    """Rise time (10-90 %), settling time (2 %), overshoot (%) and peak of a step response.

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
        Keys ``rise_time_s``, ``settling_time_s``, ``overshoot_pct``, ``peak``.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    yf = float(y[-1]) if final_value is None else float(final_value)
    peak = float(np.max(np.abs(y)))
    if not np.isfinite(yf) or yf == 0.0:
        return dict(rise_time_s=np.nan, settling_time_s=np.nan, overshoot_pct=np.nan, peak=peak)
    yn = y / yf

    def crossing(level: float) -> float:
        idx = np.flatnonzero(yn >= level)
        if idx.size == 0:
            return np.nan
        k = idx[0]
        if k == 0:
            return float(t[0])
        return float(t[k - 1] + (level - yn[k - 1]) * (t[k] - t[k - 1]) / (yn[k] - yn[k - 1]))

    rise = crossing(0.9) - crossing(0.1)
    outside = np.flatnonzero(np.abs(yn - 1.0) > settling_band)
    if outside.size == 0:
        settle = float(t[0])
    elif outside[-1] == yn.size - 1:
        settle = np.nan
    else:
        settle = float(t[outside[-1] + 1])
    overshoot = max(0.0, float(np.max(yn) - 1.0) * 100.0)
    return dict(rise_time_s=float(rise), settling_time_s=settle, overshoot_pct=overshoot, peak=peak)


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
    return StepResult(_ro(t), _ro(y), info["rise_time_s"], info["settling_time_s"],
                      info["overshoot_pct"], info["peak"], fv)
