"""Influence coefficients of constructive parameters on dynamic criteria (paper eq. 2-3).

Olaru & Olaru (2011) define, for a dynamic-behaviour criterion PCD (response time,
peak acceleration, resonance and critical frequency) and a constructive-functional
parameter PCF (area, volume, mass), the relative changes
``R_PCD = (PCD_i - PCD_f) / PCD_i`` and ``R_PCF = (PCF_i - PCF_f) / PCF_i`` and the
influence coefficient ``C = R_PCD / R_PCF``: a finite-difference *elasticity*
``d ln PCD / d ln PCF``.

Here the coefficient is evaluated by a central difference of relative changes around the
nominal point (``method="central"``, the default)::

    C = [PCD(p (1 + h)) - PCD(p (1 - h))] / PCD(p) / (2 h)

which is exact for a linear function and for ``PCD = p^2`` (C = 2), and has an
O(h^2) error otherwise; ``method="paper"`` gives the paper's one-sided ratio from an
initial to a final parameter value.  Signs are kept: C > 0 means that raising the
parameter raises the criterion.

References
----------
.. [1] A. Olaru and S. Olaru, "Assisted dynamic behavior optimization with LabVIEW
   instrumentation", Proc. CSIT vol. 1, 2011, eq. (2)-(3) and Table 1.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Literal, Mapping, Sequence

import control
import numpy as np
from scipy import optimize

from vibroscope.instruments.lti import bode, step_response
from vibroscope.instruments.pneumatic import PNEUMATIC_NOMINAL, pneumatic_motor

__all__ = [
    "influence_coefficient",
    "paper_coefficient",
    "relative_change",
    "time_grid",
    "differentiate",
    "response_time",
    "peak_acceleration",
    "resonance_frequency",
    "critical_frequency",
    "PNEUMATIC_CRITERIA",
    "InfluenceTable",
    "influence_table",
    "pneumatic_influence_table",
    "ClaimCheck",
    "check_paper_claims",
]


def relative_change(initial: float, final: float) -> float:
    """Paper eq. (2): ``(initial - final) / initial``.

    Parameters
    ----------
    initial : float
        The initial value, non-zero (any unit).
    final : float
        The final value, same unit.

    Returns
    -------
    float
        Dimensionless; positive when the value decreased.

    Raises
    ------
    ValueError
        If `initial` is 0.
    """
    if initial == 0:
        raise ValueError(f"{initial=} must be non-zero for a relative change")
    return (initial - final) / initial


def influence_coefficient(
    func: Callable[..., float],
    nominal: Mapping[str, float],
    param: str,
    *,
    rel_step: float = 0.05,
    method: Literal["central", "paper"] = "central",
    final: float | None = None,
) -> float:
    """Influence coefficient ``C = R_PCD / R_PCF`` of parameter `param` on criterion `func`.

    Parameters
    ----------
    func : callable
        ``func(**params) -> float``, the criterion PCD (any unit; C is dimensionless).
    nominal : mapping
        Nominal parameter values (SI).
    param : str
        The parameter PCF varied.
    rel_step : float
        Relative step h of the central difference (0 < h < 1).
    method : {"central", "paper"}
        ``"central"``: ``[f(p(1+h)) - f(p(1-h))] / f(p) / (2h)``; ``"paper"``: eq. (2)-(3)
        from ``nominal[param]`` to `final` (or to ``p (1 + h)`` when `final` is None).
    final : float, optional
        Final parameter value for ``method="paper"``.

    Returns
    -------
    float
        The dimensionless coefficient.

    Examples
    --------
    >>> round(influence_coefficient(lambda p: p**2, {"p": 3.0}, "p"), 12)
    2.0
    """
    if param not in nominal:
        raise ValueError(f"{param=} is not one of the nominal parameters {sorted(nominal)}")
    if not 0 < rel_step < 1:
        raise ValueError(f"{rel_step=} must lie in (0, 1)")
    p0 = float(nominal[param])
    f0 = float(func(**nominal))
    if method == "central":
        fp = float(func(**{**nominal, param: p0 * (1 + rel_step)}))
        fm = float(func(**{**nominal, param: p0 * (1 - rel_step)}))
        return (fp - fm) / f0 / (2.0 * rel_step)
    if method == "paper":
        pf = p0 * (1 + rel_step) if final is None else float(final)
        ff = float(func(**{**nominal, param: pf}))
        return paper_coefficient(f0, ff, p0, pf)
    raise ValueError(f"{method=} must be 'central' or 'paper'")


def paper_coefficient(pcd_initial: float, pcd_final: float, pcf_initial: float, pcf_final: float) -> float:
    """Paper eq. (2)-(3) from values: ``C = R_PCD / R_PCF``.

    Parameters
    ----------
    pcd_initial, pcd_final : float
        The criterion (PCD) at the initial and the final parameter value (any unit).
    pcf_initial, pcf_final : float
        The parameter (PCF) before and after the change (any unit).

    Returns
    -------
    float
        The dimensionless coefficient; ValueError for a zero initial value (see
        :func:`relative_change`).

    Examples
    --------
    >>> round(paper_coefficient(9.0, 36.0, 3.0, 6.0), 12)   # PCD = PCF^2 from 3 to 6
    3.0
    """
    return relative_change(pcd_initial, pcd_final) / relative_change(pcf_initial, pcf_final)


# --------------------------------------------------------------------------- criteria


def _num_den(sys):
    tf = control.tf(sys)
    return np.atleast_1d(np.squeeze(tf.num[0][0])), np.atleast_1d(np.squeeze(tf.den[0][0]))


def differentiate(sys, order: int = 1) -> control.TransferFunction:
    """``s^order * sys``: the response's `order`-th time derivative (e.g. acceleration from velocity).

    Parameters
    ----------
    sys : control.LTI
        SISO system.
    order : int
        Number of derivatives, >= 0.

    Returns
    -------
    control.TransferFunction
        ``s^order * sys``.
    """
    if order < 0:
        raise ValueError(f"{order=} must be >= 0")
    num, den = _num_den(sys)
    return control.tf(np.polymul(num, [1.0] + [0.0] * order), den)


def time_grid(*systems, n: int = 8001, horizon: float = 8.0, zero_tol: float = 1e-12) -> np.ndarray:
    """Time grid for step responses of `systems`: ``horizon`` slowest time constants, s.

    Parameters
    ----------
    *systems : control.LTI
        The systems to be simulated on one grid.
    n : int
        Number of samples.
    horizon : float
        Length of the grid in units of the slowest decay time ``1 / min |Re p|`` over the
        stable poles p of all systems (1 s when none is stable).
    zero_tol : float
        Poles with ``|p| <= zero_tol`` (integrators) are ignored, rad/s.

    Returns
    -------
    ndarray
        ``linspace(0, horizon / slowest, n)``.
    """
    p = np.concatenate([np.atleast_1d(control.poles(g)) for g in systems])
    p = p[np.abs(p) > zero_tol]
    slow = np.min(np.abs(p.real[p.real < 0])) if np.any(p.real < 0) else 1.0
    return np.linspace(0.0, horizon / slow, n)


def response_time(sys, t=None) -> float:
    """Response (answer) time t_r, s: 10-90 % rise time of the step response of `sys`.

    `sys` is a "velocity-like" system with finite DC gain (for the pneumatic motor: the
    velocity per flow, whose step is the paper's velocity characteristic).

    Parameters
    ----------
    sys : control.LTI
        SISO system (time unit s) with finite DC gain.
    t : array_like, optional
        Time grid in s; default :func:`time_grid` of `sys`.

    Returns
    -------
    float
        The rise time in s (NaN when the response does not settle or its final value is 0).
    """
    t = time_grid(sys) if t is None else t
    return float(step_response(sys, t).rise_time_s)


def peak_acceleration(sys, t=None, amplitude: float = 1.0) -> float:
    """Peak acceleration a_max: largest |d/dt| of the step response of `sys` (unit/s per unit input).

    For the pneumatic motor's velocity-per-flow system this is the peak piston
    acceleration in m/s^2 per m^3/s of flow step (the output of ``s * sys``).

    Parameters
    ----------
    sys : control.LTI
        SISO system (time unit s).
    t : array_like, optional
        Time grid in s; default :func:`time_grid` of `sys`.
    amplitude : float, optional
        Step height in the input's unit; default 1.

    Returns
    -------
    float
        ``max |d/dt y(t)|`` on `t`, in output unit per s.
    """
    t = time_grid(sys) if t is None else t
    r = control.forced_response(differentiate(sys), T=t, U=np.full(len(t), amplitude))
    return float(np.max(np.abs(r.outputs)))


def _mag(sys, w):
    """|G(j w)| at angular frequencies `w` (rad/s), by :func:`vibroscope.instruments.lti.bode`."""
    return bode(sys, np.atleast_1d(w) / (2 * np.pi)).magnitude


def resonance_frequency(sys) -> float:
    """Resonance frequency nu_r, Hz: frequency of the largest |G(j w)| (nan if no peak above DC).

    Parameters
    ----------
    sys : control.LTI
        SISO system (time unit s). The magnitude is searched on a log grid of angular
        frequencies up to 10 times the largest pole modulus, the peak refined by a
        bracketed scalar minimisation.

    Returns
    -------
    float
        Hz; NaN when the largest magnitude lies at an end of the grid.
    """
    p = control.poles(sys)
    wmax = 10.0 * max(np.max(np.abs(p)), 1e-6)
    w = np.logspace(np.log10(wmax) - 6, np.log10(wmax), 4000)
    m = _mag(sys, w)
    k = int(np.argmax(m))
    if k == 0 or k == w.size - 1:
        return float("nan")
    res = optimize.minimize_scalar(lambda x: -_mag(sys, np.exp(x))[0],
                                   bracket=(np.log(w[k - 1]), np.log(w[k]), np.log(w[k + 1])), tol=1e-12)
    return float(np.exp(res.x) / (2 * np.pi))


def critical_frequency(sys, level_db: float = -3.0) -> float:
    """Critical (cut-off) frequency nu_c, Hz: the first frequency where |G| falls `level_db`
    (default -3 dB) below its DC value (the bandwidth of ``control.bandwidth``).

    Parameters
    ----------
    sys : control.LTI
        SISO system (time unit s) with finite non-zero DC gain.
    level_db : float, optional
        The level relative to the DC gain, dB (negative); default -3.

    Returns
    -------
    float
        Hz; NaN when the magnitude never falls below the level on the searched grid (up to
        100 times the largest pole modulus).
    """
    g0 = _mag(sys, 0.0)[0]
    target = g0 * 10 ** (level_db / 20.0)
    p = control.poles(sys)
    wmax = 100.0 * max(np.max(np.abs(p)), 1e-6)
    w = np.logspace(np.log10(wmax) - 8, np.log10(wmax), 8000)
    m = _mag(sys, w)
    below = np.flatnonzero(m < target)
    if below.size == 0 or below[0] == 0:
        return float("nan")
    k = below[0]
    wc = optimize.brentq(lambda x: _mag(sys, x)[0] - target, w[k - 1], w[k], xtol=1e-14, rtol=1e-13)
    return float(wc / (2 * np.pi))


def _pneumatic_velocity(**params):
    return pneumatic_motor(**params, output="velocity")


#: Criteria of the paper's Table 1 for the pneumatic motor, each ``f(**params) -> float``:
#: t_r [s], a_max [m/s^2 per m^3/s], nu_r [Hz], nu_c [Hz], all from the velocity/flow system.
PNEUMATIC_CRITERIA: dict[str, Callable[..., float]] = {
    "t_r": lambda **p: response_time(_pneumatic_velocity(**p)),
    "a_max": lambda **p: peak_acceleration(_pneumatic_velocity(**p)),
    "nu_r": lambda **p: resonance_frequency(_pneumatic_velocity(**p)),
    "nu_c": lambda **p: critical_frequency(_pneumatic_velocity(**p)),
}


# --------------------------------------------------------------------------- table


@dataclass(frozen=True, eq=False)
class InfluenceTable:
    """Influence coefficients, one row per parameter and one column per criterion.

    Attributes
    ----------
    parameters : tuple of str
        Row names (constructive-functional parameters PCF).
    criteria : tuple of str
        Column names (dynamic criteria PCD).
    values : ndarray, shape (n_parameters, n_criteria)
        Signed dimensionless coefficients C.
    nominal : dict
        Nominal point (SI).
    method : str
        How C was evaluated (``"central, h=0.05"`` ...).
    """

    parameters: tuple[str, ...]
    criteria: tuple[str, ...]
    values: np.ndarray
    nominal: dict
    method: str

    @property
    def rows(self) -> list[dict]:
        """``[{"parameter": name, criterion: C, ...}, ...]``."""
        return [
            {"parameter": p, **{c: float(self.values[i, j]) for j, c in enumerate(self.criteria)}}
            for i, p in enumerate(self.parameters)
        ]

    def __getitem__(self, key: tuple[str, str]) -> float:
        p, c = key
        return float(self.values[self.parameters.index(p), self.criteria.index(c)])

    def to_markdown(self, digits: int = 3) -> str:
        """A GitHub-flavoured Markdown table (signed coefficients).

        Parameters
        ----------
        digits : int, optional
            Decimals of each coefficient; default 3.

        Returns
        -------
        str
            One row per parameter, one column per criterion.
        """
        head = "| parameter | " + " | ".join(self.criteria) + " |"
        sep = "|---|" + "---:|" * len(self.criteria)
        lines = [head, sep]
        for r in self.rows:
            lines.append(f"| {r['parameter']} | " + " | ".join(f"{r[c]:+.{digits}f}" for c in self.criteria) + " |")
        return "\n".join(lines)


def influence_table(
    criteria: Mapping[str, Callable[..., float]],
    nominal: Mapping[str, float],
    parameters: Sequence[str],
    *,
    rel_step: float = 0.05,
    method: Literal["central", "paper"] = "central",
) -> InfluenceTable:
    """Influence coefficients of each of `parameters` on each of `criteria` (see module doc).

    Parameters
    ----------
    criteria : mapping of str to callable
        ``name -> f(**params) -> float``.
    nominal : mapping
        Nominal parameter values (SI).
    parameters : sequence of str
        Parameters varied, one row each.
    rel_step, method
        As in :func:`influence_coefficient`.

    Returns
    -------
    InfluenceTable
        One row per parameter, one column per criterion.
    """
    vals = np.array(
        [[influence_coefficient(f, nominal, p, rel_step=rel_step, method=method) for f in criteria.values()] for p in parameters]
    )
    vals.flags.writeable = False
    return InfluenceTable(tuple(parameters), tuple(criteria), vals, dict(nominal), f"{method}, h={rel_step:g}")


def pneumatic_influence_table(nominal: Mapping[str, float] | None = None, *, rel_step: float = 0.05) -> InfluenceTable:
    """The paper's Table 1 recomputed: coefficients of A, V, m on t_r, a_max, nu_r, nu_c.

    Parameters
    ----------
    nominal : mapping, optional
        Pneumatic-motor parameters (SI); :data:`vibroscope.instruments.pneumatic.PNEUMATIC_NOMINAL`
        by default.
    rel_step : float
        Relative step of the central difference.

    Returns
    -------
    InfluenceTable
        Rows A, V, m; columns t_r, a_max, nu_r, nu_c.
    """
    nominal = dict(PNEUMATIC_NOMINAL if nominal is None else nominal)
    return influence_table(PNEUMATIC_CRITERIA, nominal, ("A", "V", "m"), rel_step=rel_step)


# --------------------------------------------------------------------------- claims


@dataclass(frozen=True)
class ClaimCheck:
    """One of the paper's statements about Table 1, checked against our coefficients.

    Attributes
    ----------
    claim : str
        The statement, paraphrased from the paper.
    holds : bool
        Whether our numbers support it.
    evidence : str
        The coefficients that decide it.
    """

    claim: str
    holds: bool
    evidence: str


def check_paper_claims(table: InfluenceTable) -> list[ClaimCheck]:
    """Check the paper's reading of Table 1 against `table` (rows A, V, m; columns t_r,
    a_max, nu_r, nu_c).

    The statements (Olaru & Olaru 2011, sec. 2) and the tests applied:

    1. "raising A raises with priority the critical frequency": ``C[A, nu_c] > 0`` and
       its magnitude is the largest of row A.
    2. "raising V raises with priority the response time t_r": ``C[V, t_r] > 0`` and
       largest of row V.
    3. "raising m raises with priority t_r and nu_c": ``C[m, t_r] > 0``, ``C[m, nu_c] > 0``
       and these are the two largest magnitudes of row m.
    4. "all dynamic parameters are influenced (most) by A": in every column, ``|C[A, .]|``
       is the largest.

    Parameters
    ----------
    table : InfluenceTable
        Influence coefficients with at least the rows ``A``, ``V``, ``m`` and the columns
        ``t_r``, ``a_max``, ``nu_r``, ``nu_c`` (e.g. from :data:`PNEUMATIC_CRITERIA`).

    Returns
    -------
    list of ClaimCheck
        Disagreement is reported as ``holds=False`` with the numbers; e.g. physics says the
        critical frequency of a mass-loaded actuator *falls* with mass.

    Raises
    ------
    ValueError
        If a required row or column is missing from `table`.
    """
    for p in ("A", "V", "m"):
        if p not in table.parameters:
            raise ValueError(f"table lacks parameter row {p!r}")
    for c in ("t_r", "a_max", "nu_r", "nu_c"):
        if c not in table.criteria:
            raise ValueError(f"table lacks criterion column {c!r}")

    def row(p):
        return {c: table[p, c] for c in table.criteria}

    def fmt(d):
        return ", ".join(f"C[{k}]={v:+.3f}" for k, v in d.items())

    out = []
    rA = row("A")
    top = max(rA, key=lambda c: abs(rA[c]))
    out.append(ClaimCheck("raising A raises mainly the critical frequency nu_c",
                          rA["nu_c"] > 0 and top == "nu_c",
                          f"row A: {fmt(rA)}; largest |C|: {top}; direction "
                          f"{'agrees' if rA['nu_c'] > 0 else 'disagrees'} (C[nu_c] {'>' if rA['nu_c'] > 0 else '<='} 0)"))
    rV = row("V")
    top = max(rV, key=lambda c: abs(rV[c]))
    out.append(ClaimCheck("raising V raises mainly the response time t_r",
                          rV["t_r"] > 0 and top == "t_r",
                          f"row V: {fmt(rV)}; largest |C|: {top}; direction "
                          f"{'agrees' if rV['t_r'] > 0 else 'disagrees'} (C[t_r] {'>' if rV['t_r'] > 0 else '<='} 0)"))
    rm = row("m")
    top2 = sorted(rm, key=lambda c: -abs(rm[c]))[:2]
    holds = rm["t_r"] > 0 and rm["nu_c"] > 0 and set(top2) == {"t_r", "nu_c"}
    note = ""
    if rm["nu_c"] < 0:
        note = " (nu_c falls with mass, as expected physically: omega_n ~ 1/sqrt(m))"
    out.append(ClaimCheck("raising m raises mainly t_r and nu_c", holds,
                          f"row m: {fmt(rm)}; two largest |C|: {top2}{note}"))
    cols = []
    ok = True
    for c in table.criteria:
        col = {p: abs(table[p, c]) for p in table.parameters}
        best = max(col, key=col.get)
        ok &= best == "A"
        cols.append(f"{c}: largest |C| from {best} ({col[best]:.3f})")
    n_a = sum(c.split("from ")[1].startswith("A ") for c in cols)
    out.append(ClaimCheck("A influences all criteria most (largest |C| in every column)", bool(ok),
                          "; ".join(cols) + f"; A leads {n_a} of {len(cols)} columns"))
    return out
