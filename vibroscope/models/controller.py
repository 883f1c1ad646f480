"""Discrete controllers that close a loop around a lumped model (zero-order hold output).

A :class:`Controller` runs at ``rate_hz`` (period ``T = 1 / rate_hz``). At each tick ``k`` it
samples the position ``q_k`` (m) of one DOF (and, if listed in ``measures``, its velocity
and acceleration), reads the logged reference ``r_k`` (m), computes a command ``c_k`` (in
its own unit: V, a valve command...) by one of the laws of :data:`LAWS`, adds the logged
feed-forward ``w_k`` if any, clips it at ``saturation`` and holds it (ZOH) until the next
tick. The driven ``[[input]]`` of the plant receives the force ``gain * c_k`` (N), plus the
input's ``offset`` and clipped at the input's ``saturation``.

Derivative estimates (used when ``"velocity"`` / ``"acceleration"`` are not in
``measures``) are backward differences of the FIR-filtered position
``p_k = sum_i h_i q_{k-i}`` (``h`` = ``velocity_filter``, default ``[1]``)::

    v_k = (p_k - p_{k-1}) / T,      a_k = (v_k - v_{k-1}) / T

(with ``h = [0.5, 0.5]`` this is the EMPS velocity of [3]_). With the error
``e_k = r_k - q_k`` the laws are (derivative terms act on the measurement, not on the
error, so a reference step does not kick the command [1]_, sec. 3.4; integrals by the
trapezoidal (Tustin) rule ``I_k = I_{k-1} + ki T (e_k + e_{k-1}) / 2`` [2]_, ch. 8)::

    P        c_k = kp e_k
    PD       c_k = kp e_k - kd v_k
    PID      c_k = kp e_k + I_k - kd v_k
    PD2      c_k = kp e_k - kd v_k - ka a_k                       (paper's hydraulic loop)
    PI_PDT1  w_k = kp e_k + I_k;  c = (td s + 1) / (t1 s + 1) w, Tustin:
             (1 + 2 t1/T) c_k = (1 + 2 td/T) w_k + (1 - 2 td/T) w_{k-1} - (1 - 2 t1/T) c_{k-1}
    cascade  c_k = kp kv e_k - kv v_k                              (EMPS eq. 6 [3]_)

Before the first tick the loop is at rest at the first measured position (histories
filled with it, ``e_{-1} = w_{-1} = c_{-1} = 0``).

References
----------
.. [1] K. J. Åström, T. Hägglund, *Advanced PID Control*, ISA, 2006, sec. 3.4 (set-point
   weighting, derivative on the measurement) and sec. 13.3 (discretisation).
.. [2] K. J. Åström, B. Wittenmark, *Computer-Controlled Systems*, 3rd ed., Prentice Hall,
   1997, ch. 8 (approximating continuous controllers: Tustin, ZOH of the output).
.. [3] A. Janot, M. Gautier, M. Brunot, "Data set and reference models of EMPS", Nonlinear
   System Identification Benchmarks workshop, 2019, eqs. (6)-(7) and sec. 2.2.
.. [4] A. Olaru, S. Olaru, "Assisted dynamic behavior optimization with LabVIEW
   instrumentation", Proc. CSIT vol. 1, IACSIT Press, 2011 (P / PD2 hydraulic loop, PI +
   PDT1 block schema).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

__all__ = ["Law", "LAWS", "MEASURES", "Controller"]

#: quantities a controller can sample from its DOF
MEASURES = ("position", "velocity", "acceleration")


@dataclass(frozen=True, kw_only=True)
class Law:
    """One control law of the vocabulary :data:`LAWS`.

    Attributes
    ----------
    name : str
        The ``law`` value (``"PD2"``).
    code : int
        Its number in the compiled kernel.
    required : tuple of str
        Gains that must be given.
    optional : tuple of str
        Gains that default to 0.
    units : dict of str to str
        Unit of each gain; ``u`` is the controller output's unit (V, ...), positions in m.
    display : str
        Its formula, as the docs show it.
    """

    name: str
    code: int
    required: tuple[str, ...]
    optional: tuple[str, ...]
    units: dict
    display: str


_U = {"kp": "u/m", "ki": "u/(m s)", "kd": "u s/m", "ka": "u s^2/m", "td": "s", "t1": "s"}
#: the control laws (one place: the model file, the kernel and the docs read it)
LAWS: dict[str, Law] = {
    law.name: law
    for law in (
        Law(name="P", code=0, required=("kp",), optional=(), units={"kp": _U["kp"]}, display="c = kp e"),
        Law(name="PD", code=1, required=("kp", "kd"), optional=(), units={k: _U[k] for k in ("kp", "kd")},
            display="c = kp e - kd v"),
        Law(name="PID", code=2, required=("kp", "ki", "kd"), optional=(), units={k: _U[k] for k in ("kp", "ki", "kd")},
            display="c = kp e + ki int(e) - kd v"),
        Law(name="PD2", code=3, required=("kp", "ka"), optional=("kd",), units={k: _U[k] for k in ("kp", "kd", "ka")},
            display="c = kp e - kd v - ka a"),
        Law(name="PI_PDT1", code=4, required=("kp", "ki", "t1"), optional=("td",),
            units={k: _U[k] for k in ("kp", "ki", "td", "t1")},
            display="c = (td s + 1)/(t1 s + 1) (kp e + ki int(e))"),
        Law(name="cascade", code=5, required=("kp", "kv"), optional=(), units={"kp": "1/s", "kv": "u s/m"},
            display="c = kp kv e - kv v"),
    )
}
#: order of the gains in the kernel's parameter row
GAIN_ORDER = ("kp", "ki", "kd", "ka", "td", "t1", "kv")


def _finite(name: str, v, *, positive: bool = False, nonneg: bool = False) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={v!r} must be a number") from None
    if not np.isfinite(f) or (positive and f <= 0) or (nonneg and f < 0):
        cond = "> 0" if positive else (">= 0" if nonneg else "finite")
        raise ValueError(f"{name}={f} must be finite and {cond}")
    return f


@dataclass(frozen=True, kw_only=True)
class Controller:
    """A discrete position controller closing a loop around a lumped model.

    Parameters
    ----------
    name : str
        Its name (default output channel ``/controller/<name>.command``).
    law : {"P", "PD", "PID", "PD2", "PI_PDT1", "cascade"}
        The control law (difference equations in the module docstring).
    gains : mapping of str to float
        The law's gains (:data:`LAWS`: ``kp`` u/m, ``ki`` u/(m s), ``kd`` u s/m, ``ka``
        u s^2/m, ``td`` and ``t1`` s; cascade ``kp`` 1/s and ``kv`` u s/m, with ``u`` the
        unit of the command). Stored as sorted ``(name, value)`` pairs.
    rate_hz : float
        Sample rate in Hz, > 0; the command is held (ZOH) between ticks.
    dof : str
        The DOF whose motion is measured.
    drives : int or str
        The plant ``[[input]]`` it drives: its index or its channel.
    reference : str, optional
        Logged channel of the position reference (m), e.g. ``/emps/qg.x``; None: ``r = 0``.
    measures : tuple of str
        Quantities sampled from the DOF (:data:`MEASURES`); ``"position"`` is always
        sampled, ``"velocity"`` / ``"acceleration"`` replace the backward-difference
        estimates by the sampled states. Default ``("position",)``.
    velocity_filter : sequence of float, optional
        FIR taps ``h`` on the position before differencing (``[0.5, 0.5]``: EMPS).
    gain : float
        Actuator gain, N per command unit (EMPS ``gtau`` N/V); default 1.
    saturation : float, optional
        Limit of the command, in its unit: ``c = clip(c, -saturation, saturation)``.
    output_channel : str, optional
        Logged channel of the command (``/emps/vir.x``), compared like any output.
    output_unit : str
        Unit of the command (``"V"``); default ``"1"``.
    feedforward : str, optional
        Logged channel added to the command before saturation (command unit; the EMPS
        validation pulses).

    Raises
    ------
    ValueError
        If `law` is unknown, a required gain is missing, a gain is unknown or not finite,
        `rate_hz`, `gain` or `saturation` are not positive, `measures` names an unknown
        quantity, or `velocity_filter` is empty or not finite.

    References
    ----------
    .. [1] K. J. Åström, T. Hägglund, *Advanced PID Control*, ISA, 2006.

    Examples
    --------
    The EMPS drive's position loop (Janot et al. 2019, eq. 6):

    >>> c = Controller(name="emps", law="cascade", gains={"kp": 160.18, "kv": 243.45},
    ...                rate_hz=1000.0, dof="q", drives=0, reference="/emps/qg.x",
    ...                velocity_filter=(0.5, 0.5), gain=35.15, saturation=10.0)
    >>> c.g("kv")
    243.45
    """

    name: str
    law: str
    gains: tuple
    rate_hz: float
    dof: str
    drives: int | str = 0
    reference: str | None = None
    measures: tuple[str, ...] = ("position",)
    velocity_filter: tuple[float, ...] | None = None
    gain: float = 1.0
    saturation: float | None = None
    output_channel: str | None = None
    output_unit: str = "1"
    feedforward: str | None = None

    def __post_init__(self) -> None:
        if self.law not in LAWS:
            raise ValueError(f"law={self.law!r} must be one of {tuple(LAWS)}")
        law = LAWS[self.law]
        gains = dict(self.gains.items() if isinstance(self.gains, Mapping) else self.gains)
        for k in gains:
            if k not in law.required + law.optional:
                raise ValueError(f"gain {k!r} is not a gain of law {self.law!r}: {law.required + law.optional}")
        for k in law.required:
            if k not in gains:
                raise ValueError(f"law {self.law!r} needs gain {k!r} ({law.units[k]})")
        gains = {k: _finite(k, v, nonneg=k in ("td", "t1")) for k, v in gains.items()}
        if self.law == "PI_PDT1" and gains["t1"] <= 0:
            raise ValueError(f"t1={gains['t1']} must be > 0 s")
        object.__setattr__(self, "gains", tuple(sorted(gains.items())))
        object.__setattr__(self, "name", str(self.name))
        object.__setattr__(self, "dof", str(self.dof))
        object.__setattr__(self, "rate_hz", _finite("rate_hz", self.rate_hz, positive=True))
        object.__setattr__(self, "gain", _finite("gain", self.gain))
        if self.gain == 0:
            raise ValueError(f"gain={self.gain} must be nonzero (N per command unit)")
        if self.saturation is not None:
            object.__setattr__(self, "saturation", _finite("saturation", self.saturation, positive=True))
        meas = (self.measures,) if isinstance(self.measures, str) else tuple(self.measures)
        for m in meas:
            if m not in MEASURES:
                raise ValueError(f"measures={meas!r}: {m!r} must be one of {MEASURES}")
        object.__setattr__(self, "measures", tuple(m for m in MEASURES if m in meas or m == "position"))
        if self.velocity_filter is not None:
            taps = tuple(float(h) for h in self.velocity_filter)
            if not taps or not all(np.isfinite(taps)):
                raise ValueError(f"velocity_filter={self.velocity_filter!r} must be finite FIR taps")
            object.__setattr__(self, "velocity_filter", taps)
        if not isinstance(self.drives, (int, str)) or isinstance(self.drives, bool):
            raise ValueError(f"drives={self.drives!r} must be an input index or channel")

    def g(self, name: str) -> float:
        """Gain `name` (0.0 for an optional gain not given).

        Parameters
        ----------
        name : str
            A gain of the law (``"kp"``...).

        Returns
        -------
        float
        """
        return dict(self.gains).get(name, 0.0)

    @property
    def period(self) -> float:
        """Sample period ``1 / rate_hz`` in s."""
        return 1.0 / self.rate_hz

    @property
    def command_channel(self) -> str:
        """Channel of the command: `output_channel`, default ``/controller/<name>.command``."""
        return self.output_channel or f"/controller/{self.name}.command"

    @property
    def taps(self) -> tuple[float, ...]:
        """The FIR taps on the position before differencing (``(1.0,)`` when none)."""
        return self.velocity_filter or (1.0,)
