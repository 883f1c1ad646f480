"""The founding paper's linear pneumatic motor (instrument a): piston motion per air flow.

Olaru & Olaru (2011) describe a LabVIEW instrument for a linear pneumatic motor and the
influence of its constructive parameters.  :func:`pneumatic_motor` gives the motor as a
python-control transfer function; :func:`vibroscope.viewers.instruments.figure_pneumatic`
draws the paper's figures 2-3 and :mod:`vibroscope.instruments.influence` its Table 1.

All quantities are SI (m, kg, s, N, Pa, m^3/s) unless a name says otherwise
(``*_cm2`` etc. are only used for the paper's tabulated values).

References
----------
.. [1] A. Olaru and S. Olaru, "Assisted dynamic behavior optimization with LabVIEW
   instrumentation", Proc. CSIT vol. 1, IACSIT Press, Singapore, 2011, eq. (1)-(3).
"""

from __future__ import annotations

from typing import Literal

import control
import numpy as np

from vibroscope.instruments.lti import clean_tf

__all__ = [
    "PNEUMATIC_NOMINAL",
    "PNEUMATIC_RANGES",
    "pneumatic_motor",
    "pneumatic_natural_frequency_rad_s",
]

#: Paper's parameter ranges (eq. 1 legend) converted to SI: (low, high).
#: A: cm^2 -> 1e-4 m^2; V: cm^3 -> 1e-6 m^3; m: daN s^2/cm -> 1000 kg;
#: a_m: cm^5/(daN s) -> 1e-11 m^5/(N s); b_m: daN s/cm -> 1000 N s/m; dp: daN/cm^2 -> 1e5 Pa;
#: Q: cm^3/s -> 1e-6 m^3/s.
PNEUMATIC_RANGES: dict[str, tuple[float, float]] = {
    "A": (50e-4, 80e-4),  # m^2
    "V": (500e-6, 1000e-6),  # m^3
    "m": (100.0, 600.0),  # kg
    "a_m": (0.2e-11, 0.7e-11),  # m^5/(N s)
    "b_m": (800.0, 1800.0),  # N s/m
    "dp": (4e5, 6e5),  # Pa
    "Q": (20e-6, 100e-6),  # m^3/s
}

#: Nominal point used in this package: mid-range of each interval, A = 70 cm^2 (the middle
#: of the paper's figure 2 sweep 60/70/80 cm^2), chi = 1.4.
PNEUMATIC_NOMINAL: dict[str, float] = {
    "A": 70e-4,
    "V": 750e-6,
    "m": 350.0,
    "a_m": 0.45e-11,
    "b_m": 1300.0,
    "chi": 1.4,
    "dp": 5e5,
}


def _pneumatic_coeffs(A, V, m, a_m, b_m, chi, dp):
    for name, v in dict(A=A, V=V, m=m, b_m=b_m, chi=chi, dp=dp).items():
        if not np.isfinite(v) or v <= 0:
            raise ValueError(f"{name}={v!r} must be positive and finite (SI units)")
    if not np.isfinite(a_m) or a_m < 0:
        raise ValueError(f"{a_m=} must be non-negative (m^5/(N s))")
    c = V / (chi * dp)  # pneumatic capacitance, m^5/N
    return c * m, c * b_m + m * a_m, A**2 + a_m * b_m


def pneumatic_motor(
    A: float = PNEUMATIC_NOMINAL["A"],
    V: float = PNEUMATIC_NOMINAL["V"],
    m: float = PNEUMATIC_NOMINAL["m"],
    a_m: float = PNEUMATIC_NOMINAL["a_m"],
    b_m: float = PNEUMATIC_NOMINAL["b_m"],
    chi: float = 1.4,
    dp: float = PNEUMATIC_NOMINAL["dp"],
    *,
    output: Literal["displacement", "velocity", "acceleration"] = "displacement",
) -> control.TransferFunction:
    """Linear pneumatic motor of the paper, eq. (1)-(3): piston displacement per air flow.

    Parameters
    ----------
    A : float
        Active piston area, m^2 (paper: 50-80 cm^2 = 5e-3 - 8e-3 m^2).
    V : float
        Air volume of the motor chamber, m^3 (paper: 500-1000 cm^3 = 5e-4 - 1e-3 m^3).
    m : float
        Mass reduced to the piston axis, kg (paper: 0.1-0.6 daN s^2/cm = 100-600 kg,
        since 1 daN s^2/cm = 10 N s^2 / 0.01 m = 1000 kg).
    a_m : float
        Leakage-flow gradient with pressure, m^5/(N s) (paper: 0.2-0.7 cm^5/(daN s);
        1 cm^5/(daN s) = 1e-10 m^5 / (10 N s) = 1e-11 m^5/(N s)).
    b_m : float
        Viscous friction gradient, N s/m (paper: 0.8-1.8 daN s/cm = 800-1800 N s/m).
    chi : float
        Polytropic (adiabatic) exponent, dimensionless (1.4 for air).
    dp : float
        Working pressure used in the linearisation ``p V^chi = const``, Pa (paper's
        Delta p: 4-6 daN/cm^2 = 4e5 - 6e5 Pa).
    output : {"displacement", "velocity", "acceleration"}
        Output quantity: z in m, dz/dt in m/s or d^2z/dt^2 in m/s^2.

    Returns
    -------
    control.TransferFunction
        Output per air flow Q (input in m^3/s):
        ``z(s)/Q(s) = A / (s [c m s^2 + (c b_m + m a_m) s + (A^2 + a_m b_m)])``
        with the pneumatic capacitance ``c = V / (chi dp)`` (m^5/N); velocity and
        acceleration multiply by s and s^2.

    Notes
    -----
    Linearised equations (paper eq. 1, resisting force F_r dropped as a constant
    disturbance): mass balance with compressibility ``Q = A z' + (V/(chi p)) p' + a_m p``
    and force balance ``m z'' + b_m z' = A p``.  Eliminating p gives eq. (3) above.
    The second-order factor has ``omega_n^2 = (A^2 + a_m b_m)/(c m)`` and
    ``2 zeta omega_n = (c b_m + m a_m)/(c m)``; see :func:`pneumatic_natural_frequency_rad_s`.

    Examples
    --------
    >>> g = pneumatic_motor(output="velocity")
    >>> round(float(control.dcgain(g)) * 70e-4, 3)     # ~ 1/A at DC: v = Q/A (leakage 0.01 %)
    1.0
    """
    a2, a1, a0 = _pneumatic_coeffs(A, V, m, a_m, b_m, chi, dp)
    den = [a2, a1, a0, 0.0]
    num = {"displacement": [A], "velocity": [A, 0.0], "acceleration": [A, 0.0, 0.0]}
    if output not in num:
        raise ValueError(f"{output=} must be one of {tuple(num)}")
    g = control.tf(num[output], den)
    return clean_tf(g) if output != "displacement" else control.tf(np.array([A]) / a2, np.array(den) / a2)


def pneumatic_natural_frequency_rad_s(
    A: float = PNEUMATIC_NOMINAL["A"],
    V: float = PNEUMATIC_NOMINAL["V"],
    m: float = PNEUMATIC_NOMINAL["m"],
    a_m: float = PNEUMATIC_NOMINAL["a_m"],
    b_m: float = PNEUMATIC_NOMINAL["b_m"],
    chi: float = 1.4,
    dp: float = PNEUMATIC_NOMINAL["dp"],
) -> tuple[float, float]:
    """Analytical natural angular frequency (rad/s) and damping ratio of eq. (3)'s quadratic.

    Parameters are those of :func:`pneumatic_motor` (SI); defaults the nominal
    values :data:`PNEUMATIC_NOMINAL`.

    Parameters
    ----------
    A : float, optional
        Active piston area, m^2.
    V : float, optional
        Air volume of the motor chamber, m^3.
    m : float, optional
        Mass reduced to the piston axis, kg.
    a_m : float, optional
        Leakage-flow gradient with pressure, m^5/(N s).
    b_m : float, optional
        Viscous friction gradient, N s/m.
    chi : float, optional
        Polytropic exponent, dimensionless; default 1.4 (air).
    dp : float, optional
        Working pressure of the linearisation, Pa.

    Returns
    -------
    omega_n : float
        ``sqrt((A^2 + a_m b_m) chi dp / (V m))`` in rad/s.
    zeta : float
        ``(c b_m + m a_m) / (2 sqrt(c m (A^2 + a_m b_m)))`` with ``c = V/(chi dp)``.
    """
    a2, a1, a0 = _pneumatic_coeffs(A, V, m, a_m, b_m, chi, dp)
    wn = np.sqrt(a0 / a2)
    return float(wn), float(a1 / (2.0 * np.sqrt(a2 * a0)))
