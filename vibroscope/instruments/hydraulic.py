"""The founding paper's linear hydraulic motor (instrument c) under P and PD2 position control.

Olaru & Olaru (2011) compare proportional and PD2 (position, velocity and acceleration
feedback) control of a linear hydraulic motor.  Its plant data are not in the text, so
the valve-controlled cylinder of Merritt (1967) is used: :func:`hydraulic_motor`,
:func:`hydraulic_closed_loop` and the comparison :func:`hydraulic_comparison`
(:func:`vibroscope.viewers.instruments.figure_hydraulic` draws it).

All quantities are SI (m, kg, s, N, Pa, m^3/s).

References
----------
.. [1] A. Olaru and S. Olaru, "Assisted dynamic behavior optimization with LabVIEW
   instrumentation", Proc. CSIT vol. 1, IACSIT Press, Singapore, 2011.
.. [2] H. E. Merritt, *Hydraulic Control Systems*, Wiley, 1967, ch. 5-6 (valve-controlled
   piston, hydraulic natural frequency, position servo gain limits).
.. [3] K. Ogata, *Modern Control Engineering*, 5th ed., Prentice Hall, 2010.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import control
import numpy as np

from vibroscope.instruments.lti import StepResult, step_response

__all__ = [
    "HYDRAULIC_NOMINAL",
    "hydraulic_motor",
    "hydraulic_natural_frequency_rad_s",
    "hydraulic_closed_loop",
    "HydraulicComparison",
    "hydraulic_comparison",
    "step_velocity",
]

#: Documented valve-controlled cylinder (Merritt 1967 notation), SI.
#: beta_e: effective bulk modulus of oil with hoses and entrained air, Pa (Merritt uses
#: 1e9 Pa-ish "effective" values; pure oil ~1.4e9); A: piston area, m^2 (bore 50 mm, rod
#: 28 mm annulus-averaged, ~1.35e-3 m^2 taken as 1.2e-3); V_t: total compressed volume of
#: both chambers and lines, m^3; m_t: total moving mass, kg; zeta_h: hydraulic damping
#: ratio (Merritt: typically 0.1-0.2); K_q: valve flow gain, m^3/s per unit command (a
#: 30 L/min servovalve at full command: 5e-4 m^3/s).
HYDRAULIC_NOMINAL: dict[str, float] = {
    "beta_e": 1.0e9,
    "A": 1.2e-3,
    "V_t": 6.0e-4,
    "m_t": 150.0,
    "zeta_h": 0.15,
    "K_q": 5.0e-4,
}


def hydraulic_natural_frequency_rad_s(beta_e: float, A: float, V_t: float, m_t: float) -> float:
    """Merritt's hydraulic natural frequency ``omega_h = sqrt(4 beta_e A^2 / (V_t m_t))`` in rad/s.

    Parameters
    ----------
    beta_e : float
        Effective bulk modulus, Pa.
    A : float
        Piston area, m^2.
    V_t : float
        Total compressed volume of both chambers, m^3.
    m_t : float
        Total moving mass, kg.

    Returns
    -------
    float
        The natural frequency ``omega_h`` in rad/s.
    """
    for name, v in dict(beta_e=beta_e, A=A, V_t=V_t, m_t=m_t).items():
        if not np.isfinite(v) or v <= 0:
            raise ValueError(f"{name}={v!r} must be positive and finite (SI)")
    return float(np.sqrt(4.0 * beta_e * A**2 / (V_t * m_t)))


def hydraulic_motor(
    beta_e: float = HYDRAULIC_NOMINAL["beta_e"],
    A: float = HYDRAULIC_NOMINAL["A"],
    V_t: float = HYDRAULIC_NOMINAL["V_t"],
    m_t: float = HYDRAULIC_NOMINAL["m_t"],
    zeta_h: float = HYDRAULIC_NOMINAL["zeta_h"],
    K_q: float = HYDRAULIC_NOMINAL["K_q"],
) -> control.TransferFunction:
    """Valve-controlled linear hydraulic motor (Merritt 1967): piston position per valve command.

    Parameters
    ----------
    beta_e, A, V_t, m_t : float
        Bulk modulus (Pa), piston area (m^2), total volume (m^3), moving mass (kg).
    zeta_h : float
        Hydraulic damping ratio, dimensionless.
    K_q : float
        Valve flow gain, m^3/s per unit (dimensionless, normalised) valve command.

    Returns
    -------
    control.TransferFunction
        ``x/u = (K_q/A) / (s (s^2/omega_h^2 + 2 zeta_h s/omega_h + 1))`` (m per unit command),
        with ``omega_h`` from :func:`hydraulic_natural_frequency_rad_s`; no external spring load.
    """
    wh = hydraulic_natural_frequency_rad_s(beta_e, A, V_t, m_t)
    kv = K_q / A
    return control.tf([kv], [1.0 / wh**2, 2.0 * zeta_h / wh, 1.0, 0.0])


def hydraulic_closed_loop(k_p: float, k_d: float = 0.0, k_a: float = 0.0, **plant) -> control.TransferFunction:
    """Position loop of the hydraulic motor with the PD2 law (P: ``k_d = k_a = 0``).

    Control law (derivative terms on the measured output, so a reference step does not
    kick the valve): ``u = k_p (r - x) - k_d x' - k_a x''``; units: k_p in 1/m, k_d in s/m,
    k_a in s^2/m (u is dimensionless valve command).

    Parameters
    ----------
    k_p : float
        Proportional position gain, 1/m.
    k_d : float
        Velocity (derivative) feedback gain, s/m.
    k_a : float
        Acceleration (second-derivative) feedback gain, s^2/m.
    **plant
        Overrides of :data:`HYDRAULIC_NOMINAL` (``beta_e`` Pa, ``A`` m^2, ``V_t`` m^3,
        ``m_t`` kg, ``zeta_h``, ``K_q`` m^3/s).

    Returns
    -------
    control.TransferFunction
        The ratio x/r, dimensionless; DC gain 1 (the plant integrates).
    """
    p = dict(HYDRAULIC_NOMINAL, **plant)
    wh = hydraulic_natural_frequency_rad_s(p["beta_e"], p["A"], p["V_t"], p["m_t"])
    kv = p["K_q"] / p["A"]
    den = [1.0 / wh**2, 2.0 * p["zeta_h"] / wh + kv * k_a, 1.0 + kv * k_d, kv * k_p]
    return control.tf([kv * k_p], den)


@dataclass(frozen=True, eq=False, kw_only=True)
class HydraulicComparison:
    """Proportional versus PD2 position control of the linear hydraulic motor.

    Attributes
    ----------
    omega_h : float
        Hydraulic natural frequency, rad/s.
    zeta_h : float
        Hydraulic damping ratio of the open plant.
    gains_p : dict
        ``{"k_p": ...}`` of the proportional loop (1/m).
    gains_pd2 : dict
        ``{"k_p", "k_d", "k_a"}`` of the PD2 loop (1/m, s/m, s^2/m).
    tuning : str
        How the gains were chosen.
    step_p, step_pd2 : StepResult
        Unit reference step responses (dimensionless).
    acc_time_p, acc_time_pd2 : float
        Acceleration time, s: time at which the piston velocity reaches its peak.
    settling_reduction_pct, oscillation_reduction_pct, acceleration_time_reduction_pct : float
        ``100 (P - PD2) / P`` of the 2 % settling time, of the oscillation measure and of
        the acceleration time.
    oscillation_p, oscillation_pd2 : float
        Oscillation measure: velocity reversal ratio, the largest backward piston velocity
        after the velocity peak divided by the peak velocity (the P loop's hydraulic
        ringing shows in the velocity as the piston stops and reverses; dimensionless).
    """

    omega_h: float
    zeta_h: float
    gains_p: dict
    gains_pd2: dict
    tuning: str
    step_p: StepResult
    step_pd2: StepResult
    acc_time_p: float
    acc_time_pd2: float
    oscillation_p: float
    oscillation_pd2: float
    settling_reduction_pct: float
    oscillation_reduction_pct: float
    acceleration_time_reduction_pct: float

    def summary(self) -> str:
        """A short text table of the comparison."""
        return (
            f"hydraulic motor: omega_h = {self.omega_h:.1f} rad/s ({self.omega_h / 2 / np.pi:.1f} Hz), "
            f"zeta_h = {self.zeta_h:.2f}; tuning: {self.tuning}\n"
            f"{'':14s}{'P':>10s}{'PD2':>10s}{'reduction':>11s}\n"
            f"{'settling [ms]':14s}{1e3 * self.step_p.settling_time_s:10.1f}{1e3 * self.step_pd2.settling_time_s:10.1f}"
            f"{self.settling_reduction_pct:10.0f}%\n"
            f"{'acc. time [ms]':14s}{1e3 * self.acc_time_p:10.1f}{1e3 * self.acc_time_pd2:10.1f}"
            f"{self.acceleration_time_reduction_pct:10.0f}%\n"
            f"{'vel. reversal':14s}{self.oscillation_p:10.3f}{self.oscillation_pd2:10.3f}"
            f"{self.oscillation_reduction_pct:10.0f}%\n"
            f"{'overshoot [%]':14s}{self.step_p.overshoot_pct:10.2f}{self.step_pd2.overshoot_pct:10.2f}"
        )

    def plot(self, axes=None):
        """Step responses and velocities of both loops
        (:func:`vibroscope.viewers.instruments.plot_hydraulic_comparison`).

        Parameters
        ----------
        axes : sequence of 2 matplotlib.axes.Axes, optional
            Position and velocity axes; default a new figure.

        Returns
        -------
        (Axes, Axes)
        """
        from vibroscope._plotting import draw

        return draw("plot_hydraulic_comparison", self, axes)


def step_velocity(r: StepResult) -> np.ndarray:
    """Piston velocity of a position step response, ``d response / dt`` (second-order
    central differences), in response unit per s.

    Parameters
    ----------
    r : StepResult
        A step response (``time_s`` in s, ``response``).

    Returns
    -------
    ndarray, shape (n_t,)
        ``numpy.gradient(response, time_s)``.
    """
    return np.gradient(np.asarray(r.response), np.asarray(r.time_s))


def _oscillation(r: StepResult) -> float:
    """Velocity reversal ratio: largest backward piston velocity after the velocity peak,
    over the peak velocity (0 for a response that never moves backwards)."""
    v = step_velocity(r)
    k = int(np.argmax(v))
    return float(max(0.0, -float(np.min(v[k:]))) / v[k]) if v[k] > 0 else float("nan")


def _acc_time(r: StepResult) -> float:
    v = step_velocity(r)
    return float(r.time_s[int(np.argmax(v))])


def hydraulic_comparison(
    *,
    gain_margin_db: float = 6.0,
    tuning: Literal["itae", "same-gain"] = "itae",
    zeta_target: float = 0.7,
    t_end: float = 0.25,
    **plant,
) -> HydraulicComparison:
    """Compare proportional and PD2 position control of the linear hydraulic motor.

    Parameters
    ----------
    gain_margin_db : float
        Gain margin (dB) that sets the proportional loop (Merritt's rule: the phase
        crosses -180 deg at omega_h, where the loop gain is ``K_v / (2 zeta_h omega_h)``;
        ``K_v = k_p K_q / A`` in 1/s).  6 dB gives ``K_v = zeta_h omega_h``.
    tuning : {"itae", "same-gain"}
        How the PD2 gains are chosen.  ``"itae"`` (default): pole placement of the closed
        loop ``s^3/omega_h^2 + (2 zeta_h/omega_h + K k_a) s^2 + (1 + K k_d) s + K k_p``
        (K = K_q/A) onto the ITAE-optimal third-order polynomial
        ``s^3 + 1.75 w0 s^2 + 2.15 w0^2 s + w0^3`` (Graham & Lathrop 1953), with
        ``k_d = 0`` which fixes ``w0 = omega_h / sqrt(2.15)``.  ``"same-gain"``: PD2 keeps
        the P loop's k_p (same static stiffness, same initial valve command) and the
        acceleration feedback only raises the resonance damping to `zeta_target`.
    zeta_target : float
        Damping ratio of the resonance for ``tuning="same-gain"``:
        ``K k_a = 2 (zeta_target - zeta_h) / omega_h``.
    t_end : float
        Simulated time, s.
    **plant
        Overrides of :data:`HYDRAULIC_NOMINAL`.

    Returns
    -------
    HydraulicComparison

    Notes
    -----
    The paper reports that PD2 cut the acceleration time and the oscillation by about
    50 % "for the same constructive and functional parameters"; its plant data are not in
    the text, so :data:`HYDRAULIC_NOMINAL` (a 40 Hz servo-cylinder) is used instead.
    The "D" (velocity) term of PD2 is kept at zero: on this type-1 plant it only lowers
    the effective loop gain; the damping comes from the second-derivative term.

    References
    ----------
    .. [1] H. E. Merritt, *Hydraulic Control Systems*, Wiley, 1967, sec. 6.
    .. [2] D. Graham and R. C. Lathrop, "The synthesis of optimum transient response:
       criteria and standard forms", Trans. AIEE 72(5), 1953.
    """
    p = dict(HYDRAULIC_NOMINAL, **plant)
    wh = hydraulic_natural_frequency_rad_s(p["beta_e"], p["A"], p["V_t"], p["m_t"])
    zh = p["zeta_h"]
    kq_a = p["K_q"] / p["A"]
    k_p = 10 ** (-gain_margin_db / 20.0) * 2.0 * zh * wh / kq_a
    k_p2, k_a, how = _pd2_gains(tuning, k_p, wh, zh, kq_a, zeta_target)
    how = f"P at {gain_margin_db:g} dB gain margin (K_v = {k_p * kq_a:.1f} 1/s); {how}"
    t = np.linspace(0.0, t_end, 10001)
    sp = step_response(hydraulic_closed_loop(k_p, **p), t)
    sd = step_response(hydraulic_closed_loop(k_p2, 0.0, k_a, **p), t)
    op, od = _oscillation(sp), _oscillation(sd)
    ap, ad = _acc_time(sp), _acc_time(sd)
    return HydraulicComparison(
        omega_h=wh,
        zeta_h=zh,
        gains_p={"k_p": k_p},
        gains_pd2={"k_p": k_p2, "k_d": 0.0, "k_a": k_a},
        tuning=f"{tuning}: {how}",
        step_p=sp,
        step_pd2=sd,
        acc_time_p=ap,
        acc_time_pd2=ad,
        oscillation_p=op,
        oscillation_pd2=od,
        settling_reduction_pct=_reduction(sp.settling_time_s, sd.settling_time_s),
        oscillation_reduction_pct=_reduction(op, od),
        acceleration_time_reduction_pct=_reduction(ap, ad),
    )


def _pd2_gains(tuning: str, k_p: float, wh: float, zh: float, kq_a: float, zeta_target: float):
    """``(k_p, k_a, description)`` of the PD2 loop (see :func:`hydraulic_comparison`)."""
    if tuning == "itae":
        w0 = wh / np.sqrt(2.15)
        k_a = (1.75 * w0 / wh**2 - 2.0 * zh / wh) / kq_a
        k_p2 = w0**3 / wh**2 / kq_a
        how = (f"PD2 by pole placement on the ITAE 3rd-order form, k_d = 0, w0 = omega_h/sqrt(2.15) "
               f"(K_v = {k_p2 * kq_a:.1f} 1/s)")
    elif tuning == "same-gain":
        k_a = 2.0 * (zeta_target - zh) / wh / kq_a
        k_p2 = k_p
        how = f"PD2 same k_p, acceleration feedback raising the resonance damping to {zeta_target:g}"
    else:
        raise ValueError(f"{tuning=} must be 'itae' or 'same-gain'")
    if k_a < 0:
        raise ValueError(f"the plant is already better damped than the target ({zh=}); {k_a=} < 0")
    return k_p2, k_a, how


def _reduction(p: float, pd2: float) -> float:
    """``100 (P - PD2) / P`` in %, nan unless P > 0."""
    return float(100.0 * (p - pd2) / p) if p > 0 else float("nan")
