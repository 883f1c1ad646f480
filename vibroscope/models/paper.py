"""The founding paper's virtual instruments, rebuilt as scriptable models.

Olaru & Olaru (2011) describe LabVIEW instruments for (a) a linear pneumatic motor and the
influence of its constructive parameters, (c) a linear hydraulic motor under proportional
and PD2 position control, and (d) a block schema with a PI regulator and a first-order
correction, showing the indicial response at every point.  This module gives each one as
a function returning python-control objects or frozen results, and a figure function.

All quantities are SI (m, kg, s, N, Pa, m^3/s) unless a name says otherwise
(``*_cm2`` etc. are only used for the paper's tabulated values).

References
----------
.. [1] A. Olaru and S. Olaru, "Assisted dynamic behavior optimization with LabVIEW
   instrumentation", Proc. CSIT vol. 1, IACSIT Press, Singapore, 2011, eq. (1)-(4).
.. [2] H. E. Merritt, *Hydraulic Control Systems*, Wiley, 1967, ch. 5-6 (valve-controlled
   piston, hydraulic natural frequency, position servo gain limits).
.. [3] K. Ogata, *Modern Control Engineering*, 5th ed., Prentice Hall, 2010.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import control
import numpy as np

from vibroscope.models.lti import (
    Block,
    BlockSchema,
    StepResult,
    Sum,
    bode,
    clean_tf,
    nyquist,
    step_response,
)

__all__ = [
    "PNEUMATIC_NOMINAL",
    "PNEUMATIC_RANGES",
    "pneumatic_motor",
    "pneumatic_natural_frequency",
    "figure_pneumatic",
    "HYDRAULIC_NOMINAL",
    "hydraulic_motor",
    "hydraulic_natural_frequency",
    "hydraulic_closed_loop",
    "HydraulicComparison",
    "hydraulic_comparison",
    "figure_hydraulic",
    "PI_REGULATOR",
    "CORRECTION",
    "BLOCK_SCHEMA_PLANT",
    "paper_block_schema",
    "figure_block_schema",
]

# ============================================================================ pneumatic

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
    ``2 zeta omega_n = (c b_m + m a_m)/(c m)``; see :func:`pneumatic_natural_frequency`.

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


def pneumatic_natural_frequency(
    A: float = PNEUMATIC_NOMINAL["A"],
    V: float = PNEUMATIC_NOMINAL["V"],
    m: float = PNEUMATIC_NOMINAL["m"],
    a_m: float = PNEUMATIC_NOMINAL["a_m"],
    b_m: float = PNEUMATIC_NOMINAL["b_m"],
    chi: float = 1.4,
    dp: float = PNEUMATIC_NOMINAL["dp"],
) -> tuple[float, float]:
    """Analytical natural angular frequency (rad/s) and damping ratio of eq. (3)'s quadratic.

    Parameters are those of :func:`pneumatic_motor` (SI).

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


def figure_pneumatic(path, areas_cm2=(60.0, 70.0, 80.0), flow: float = 50e-6, **params) -> None:
    """Paper figures 2 and 3: displacement, velocity, acceleration step responses and
    Bode / Nyquist of the pneumatic motor for several piston areas.

    Parameters
    ----------
    path : str or path-like
        PNG file written.
    areas_cm2 : sequence of float
        Piston areas in cm^2 (converted to m^2).
    flow : float
        Step of air flow Q in m^3/s (default 50 cm^3/s, mid of the paper's 20-100 cm^3/s).
    **params
        Other :func:`pneumatic_motor` parameters (SI).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    t = np.linspace(0.0, 1.5, 3001)
    f = np.logspace(-1, 1.5, 600)
    fig, ax = plt.subplots(2, 3, figsize=(13, 7))
    for a_cm2 in areas_cm2:
        kw = dict(PNEUMATIC_NOMINAL, **params, A=a_cm2 * 1e-4)
        lab = f"A = {a_cm2:g} cm²"
        for k, (out, scale, unit) in enumerate(
            (("displacement", 1e3, "mm"), ("velocity", 1e3, "mm/s"), ("acceleration", 1e3, "mm/s²"))
        ):
            r = step_response(pneumatic_motor(**kw, output=out), t, amplitude=flow)
            ax[0, k].plot(t, r.response * scale, label=lab)
            ax[0, k].set_ylabel(f"{out} [{unit}]")
            ax[0, k].set_title(f"{out} for a {flow * 1e6:g} cm³/s flow step")
        g = pneumatic_motor(**kw, output="displacement")
        b = bode(g, f)
        ax[1, 0].semilogx(f, b.magnitude_db, label=lab)
        ax[1, 1].semilogx(f, b.phase_deg, label=lab)
        ny = nyquist(pneumatic_motor(**kw, output="velocity"), np.logspace(-2, 2, 2000))
        ax[1, 2].plot(ny.response.real * 1e-2, ny.response.imag * 1e-2, label=lab)
    for a in ax[0]:
        a.set_xlabel("time [s]")
    ax[1, 0].set_title("Bode magnitude z/Q")
    ax[1, 0].set_ylabel("|z/Q| [dB re 1 s/m²]")
    ax[1, 1].set_title("Bode phase z/Q")
    ax[1, 1].set_ylabel("phase [deg]")
    for a in ax[1, :2]:
        a.set_xlabel("frequency [Hz]")
    ax[1, 2].set_title("Nyquist of velocity/flow ż/Q")
    ax[1, 2].set_xlabel("Re ż/Q [10² m⁻²]")
    ax[1, 2].set_ylabel("Im ż/Q [10² m⁻²]")
    ax[1, 2].set_aspect("equal", adjustable="datalim")
    for a in ax.flat:
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle("Linear pneumatic motor (Olaru & Olaru 2011, eq. 3) — effect of piston area A")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


# ============================================================================ hydraulic

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


def hydraulic_natural_frequency(beta_e: float, A: float, V_t: float, m_t: float) -> float:
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
        with ``omega_h`` from :func:`hydraulic_natural_frequency`; no external spring load.
    """
    wh = hydraulic_natural_frequency(beta_e, A, V_t, m_t)
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
        x/r, dimensionless; DC gain 1 (the plant integrates).
    """
    p = dict(HYDRAULIC_NOMINAL, **plant)
    wh = hydraulic_natural_frequency(p["beta_e"], p["A"], p["V_t"], p["m_t"])
    kv = p["K_q"] / p["A"]
    den = [1.0 / wh**2, 2.0 * p["zeta_h"] / wh + kv * k_a, 1.0 + kv * k_d, kv * k_p]
    return control.tf([kv * k_p], den)


@dataclass(frozen=True, eq=False)
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
        """Step responses and velocities of both loops."""
        import matplotlib.pyplot as plt

        if axes is None:
            _, axes = plt.subplots(1, 2, figsize=(11, 4))
        for r, lab in ((self.step_p, "P"), (self.step_pd2, "PD2")):
            axes[0].plot(r.time_s * 1e3, r.response, label=f"{lab}: settling {r.settling_time_s * 1e3:.0f} ms")
            v = np.gradient(r.response, r.time_s)
            axes[1].plot(r.time_s * 1e3, v, label=lab)
        axes[0].set_ylabel("position x/r [-]")
        axes[1].set_ylabel("velocity per unit step [1/s]")
        axes[0].set_title("unit step of position reference")
        axes[1].set_title("piston velocity (acceleration phase)")
        for a in axes:
            a.set_xlabel("time [ms]")
            a.grid(True, alpha=0.3)
            a.legend()
        return axes


def _oscillation(r: StepResult) -> float:
    """Velocity reversal ratio: largest backward piston velocity after the velocity peak,
    over the peak velocity (0 for a response that never moves backwards)."""
    v = np.gradient(np.asarray(r.response), np.asarray(r.time_s))
    k = int(np.argmax(v))
    return float(max(0.0, -float(np.min(v[k:]))) / v[k]) if v[k] > 0 else float("nan")


def _acc_time(r: StepResult) -> float:
    v = np.gradient(np.asarray(r.response), np.asarray(r.time_s))
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
    wh = hydraulic_natural_frequency(p["beta_e"], p["A"], p["V_t"], p["m_t"])
    zh = p["zeta_h"]
    kq_a = p["K_q"] / p["A"]
    gm = 10 ** (-gain_margin_db / 20.0)
    k_p = gm * 2.0 * zh * wh / kq_a
    if tuning == "itae":
        w0 = wh / np.sqrt(2.15)
        k_a = (1.75 * w0 / wh**2 - 2.0 * zh / wh) / kq_a
        k_p2 = w0**3 / wh**2 / kq_a
        how = (f"P at {gain_margin_db:g} dB gain margin (K_v = {k_p * kq_a:.1f} 1/s); PD2 by pole placement "
               f"on the ITAE 3rd-order form, k_d = 0, w0 = omega_h/sqrt(2.15) (K_v = {k_p2 * kq_a:.1f} 1/s)")
    elif tuning == "same-gain":
        k_a = 2.0 * (zeta_target - zh) / wh / kq_a
        k_p2 = k_p
        how = (f"P at {gain_margin_db:g} dB gain margin (K_v = {k_p * kq_a:.1f} 1/s); PD2 same k_p, "
               f"acceleration feedback raising the resonance damping to {zeta_target:g}")
    else:
        raise ValueError(f"{tuning=} must be 'itae' or 'same-gain'")
    if k_a < 0:
        raise ValueError(f"the plant is already better damped than the target ({zh=}); {k_a=} < 0")
    t = np.linspace(0.0, t_end, 10001)
    sp = step_response(hydraulic_closed_loop(k_p, **p), t)
    sd = step_response(hydraulic_closed_loop(k_p2, 0.0, k_a, **p), t)
    op, od = _oscillation(sp), _oscillation(sd)
    ap, ad = _acc_time(sp), _acc_time(sd)

    def red(a, b):
        return float(100.0 * (a - b) / a) if a > 0 else float("nan")

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
        settling_reduction_pct=red(sp.settling_time_s, sd.settling_time_s),
        oscillation_reduction_pct=red(op, od),
        acceleration_time_reduction_pct=red(ap, ad),
    )


def figure_hydraulic(path) -> None:
    """Step and velocity responses of P versus PD2 position control (PNG at `path`)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    for row, tuning in zip(axes, ("itae", "same-gain")):
        c = hydraulic_comparison(tuning=tuning)
        c.plot(row)
        row[0].set_title(f"position step, tuning '{tuning}'")
    fig.suptitle(f"Linear hydraulic motor (Merritt 1967), ω_h = {c.omega_h / 2 / np.pi:.0f} Hz: P vs PD2")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


# ============================================================================ block schema

#: Paper eq. (4) PI regulator ``H_R(s) = 0.9 (9.9 s + 1) / (3 s)`` (dimensionless gain).
PI_REGULATOR = control.tf([0.9 * 9.9, 0.9], [3.0, 0.0])
#: Paper eq. (4) correction ``H_c(s) = 1 / (0.7 s + 1)`` (the paper calls it PDT1; as
#: printed it is a first-order lag PT1, time constant 0.7 s).
CORRECTION = control.tf([1.0], [0.7, 1.0])
#: Plant of the schema: the paper's figure 6 plant is not recoverable from the text; we use
#: a proportional-inertial second-order element (the paper's "PT2" class of robot modules)
#: ``H_p(s) = 1 / (s^2/omega_n^2 + 2 zeta s/omega_n + 1)``, omega_n = 5 rad/s, zeta = 0.7.
BLOCK_SCHEMA_PLANT = control.tf([1.0], [1.0 / 25.0, 2 * 0.7 / 5.0, 1.0])


def paper_block_schema(load: bool = False, *, closed: bool = True, plant=None) -> BlockSchema:
    """The paper's figure 6 block schema: PI regulator, correction, plant, unity feedback.

    Signals (named points): ``r`` reference, ``e = r - y`` error (``r`` itself when
    open), ``u`` regulator output, ``c`` correction output, ``v = c + d`` plant input
    (with the load disturbance ``d``), ``y`` plant output.

    Parameters
    ----------
    load : bool
        Whether the load-disturbance input ``d`` (a force-like signal added at the plant
        input, same unit as ``c``) is an exogenous input of the schema.
    closed : bool
        Unity-feedback closed loop (True) or open loop (False: ``e = r``).
    plant : control.LTI, optional
        Plant model; :data:`BLOCK_SCHEMA_PLANT` by default.

    Returns
    -------
    BlockSchema
        Use ``.transfer(point)`` / ``.step(t)`` for the indicial response at every point,
        ``.step(t, from_="d")`` for the load step.
    """
    plant = BLOCK_SCHEMA_PLANT if plant is None else plant
    blocks = (
        Block("regulator", PI_REGULATOR, "e", "u"),
        Block("correction", CORRECTION, "u", "c"),
        Block("plant", plant, "v", "y"),
    )
    sums = [Sum("e", ("r", "-y") if closed else ("r",))]
    sums.append(Sum("v", ("c", "d") if load else ("c",)))
    inputs = ("r", "d") if load else ("r",)
    title = f"PI + correction + plant, {'closed' if closed else 'open'} loop{', with load' if load else ''}"
    return BlockSchema(blocks, tuple(sums), inputs, title)


def figure_block_schema(path, load_step: float = -0.5, t_load: float = 15.0, t_end: float = 40.0) -> None:
    """Indicial responses at every point (open / closed loop, with / without load) and Bode
    of each component, as the paper's figure 7 instrument (PNG at `path`).

    Parameters
    ----------
    path : str or path-like
        PNG file written.
    load_step : float
        Height of the load disturbance step at the plant input (same unit as the reference).
    t_load : float
        Time of the load step, s.
    t_end : float
        Simulated time, s.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    t = np.linspace(0.0, t_end, 6001)
    fig, ax = plt.subplots(2, 2, figsize=(12, 8))
    cl = paper_block_schema(load=True)
    ol = paper_block_schema(load=False, closed=False)
    names = {"e": "error e", "u": "regulator out u", "c": "correction out c", "y": "plant out y", "r": "reference r"}
    dmask = (t >= t_load).astype(float) * load_step
    for point, lab in names.items():
        yr = cl.step(t)[point].response
        (ln,) = ax[0, 0].plot(t, yr, label=lab)
        if point in ("e", "y", "u"):
            g = cl.transfer(point, "d")
            yd = control.forced_response(g, T=t, U=dmask).outputs
            ax[0, 1].plot(t, yr + yd, color=ln.get_color(), label=f"{lab} (load {load_step:g} at {t_load:g} s)")
    ax[0, 1].plot(t, cl.step(t)["y"].response, "k:", lw=1, label="plant out y, no load")
    for point in ("u", "c", "y"):
        ax[1, 0].plot(t, ol.step(t)[point].response, label=names[point])
    f = np.logspace(-3, 1, 500)
    for name, b in cl.block_bode(f).items():
        ax[1, 1].semilogx(f, b.magnitude_db, label=name)
    ax[1, 1].semilogx(f, bode(cl.transfer("y"), f).magnitude_db, "k--", label="closed loop y/r")
    ax[0, 0].set_title("closed loop: unit reference step, every point")
    ax[0, 1].set_title("closed loop with a load step at the plant input")
    ax[1, 0].set_title("open loop (no feedback): unit reference step")
    ax[1, 0].set_ylim(-0.5, 15)
    ax[1, 1].set_title("Bode magnitude of each component")
    for a in (ax[0, 0], ax[0, 1], ax[1, 0]):
        a.set_xlabel("time [s]")
        a.set_ylabel("signal [unit of r]")
    ax[1, 1].set_xlabel("frequency [Hz]")
    ax[1, 1].set_ylabel("magnitude [dB]")
    for a in ax.flat:
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle("Block schema: PI H_R = 0.9(9.9s+1)/(3s), correction H_c = 1/(0.7s+1), plant PT2 (ω_n = 5 rad/s, ζ = 0.7)")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
