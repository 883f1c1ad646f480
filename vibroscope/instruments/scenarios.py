"""The founding paper's scenarios, computed: what :mod:`vibroscope.viewers.instruments` draws.

The figures of the paper (Olaru & Olaru 2011) are runs of the instruments at fixed settings; they
are computed here, in the instruments' room, and the viewer only draws the results (so that no
viewer computes a scenario, and the numbers can be checked without matplotlib).

- :func:`pneumatic_scenario`: figs. 2-3, the pneumatic motor for several piston areas;
- :func:`hydraulic_scenario`: P versus PD2 position control, both tunings;
- :func:`block_schema_scenario`: fig. 7, the PI + correction schema at every point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibroscope.instruments.block_schema import paper_block_schema
from vibroscope.instruments.hydraulic import HydraulicComparison, hydraulic_comparison
from vibroscope.instruments.lti import BodeResult, bode, nyquist, step_response
from vibroscope.instruments.pneumatic import PNEUMATIC_NOMINAL, pneumatic_motor

__all__ = ["PneumaticScenario", "pneumatic_scenario", "hydraulic_scenario", "BlockSchemaScenario",
           "block_schema_scenario", "PNEUMATIC_OUTPUTS"]

#: The pneumatic motor's outputs drawn in the step responses, in order.
PNEUMATIC_OUTPUTS = ("displacement", "velocity", "acceleration")


@dataclass(frozen=True)
class PneumaticScenario:
    """The pneumatic motor for several piston areas (paper figs. 2-3).

    Attributes
    ----------
    areas_cm2 : tuple of float
        Piston areas, cm².
    flow : float
        Flow step, m³/s.
    steps : tuple of dict of str to StepResult
        Per area, the responses to the flow step of each of :data:`PNEUMATIC_OUTPUTS`
        (m, m/s, m/s²), on ``time_s``.
    bode : tuple of BodeResult
        Per area, displacement per flow z/Q on ``frequencies``.
    nyquist : tuple of NyquistResult
        Per area, velocity per flow ż/Q (0.01 to 100 Hz).
    """

    areas_cm2: tuple
    flow: float
    steps: tuple
    bode: tuple
    nyquist: tuple


def pneumatic_scenario(areas_cm2=(60.0, 70.0, 80.0), flow: float = 50e-6, **params) -> PneumaticScenario:
    """The pneumatic motor of :func:`vibroscope.instruments.pneumatic.pneumatic_motor` for several
    piston areas: step responses over 1.5 s (3001 samples), Bode of z/Q over 0.1-31.6 Hz (600
    lines), Nyquist of ż/Q over 0.01-100 Hz (2000 lines).

    Parameters
    ----------
    areas_cm2 : sequence of float, optional
        Piston areas, cm² (default the paper's 60, 70, 80).
    flow : float, optional
        Flow step, m³/s (default 50 cm³/s).
    **params
        Other :func:`~vibroscope.instruments.pneumatic.pneumatic_motor` parameters (SI), over
        :data:`~vibroscope.instruments.pneumatic.PNEUMATIC_NOMINAL`.

    Returns
    -------
    PneumaticScenario
    """
    t = np.linspace(0.0, 1.5, 3001)
    f = np.logspace(-1, 1.5, 600)
    steps, bodes, nyqs = [], [], []
    for a_cm2 in areas_cm2:
        kw = dict(PNEUMATIC_NOMINAL, **params, A=a_cm2 * 1e-4)
        steps.append({out: step_response(pneumatic_motor(**kw, output=out), t, amplitude=flow)
                      for out in PNEUMATIC_OUTPUTS})
        bodes.append(bode(pneumatic_motor(**kw, output="displacement"), f))
        nyqs.append(nyquist(pneumatic_motor(**kw, output="velocity"), np.logspace(-2, 2, 2000)))
    return PneumaticScenario(tuple(areas_cm2), float(flow), tuple(steps), tuple(bodes), tuple(nyqs))


def hydraulic_scenario(tunings=("itae", "same-gain")) -> dict[str, HydraulicComparison]:
    """P versus PD2 position control of the hydraulic motor, for each tuning.

    Parameters
    ----------
    tunings : sequence of str, optional
        Tunings of :func:`~vibroscope.instruments.hydraulic.hydraulic_comparison` (default both).

    Returns
    -------
    dict of str to HydraulicComparison
        Tuning -> its comparison.
    """
    return {tuning: hydraulic_comparison(tuning=tuning) for tuning in tunings}


@dataclass(frozen=True, kw_only=True)
class BlockSchemaScenario:
    """The paper's PI + correction block schema at every point (paper fig. 7).

    Attributes
    ----------
    time_s : ndarray, shape (n_t,)
        Time axis, s.
    reference : dict of str to ndarray
        Closed loop, unit reference step: the signal at each point (``e``, ``u``, ``c``, ``y``,
        ``r``), shape (n_t,).
    load : dict of str to ndarray
        Closed loop, the response at each point to the load step at the plant input alone.
    load_step, t_load : float
        The load step's height (unit of r) and time (s).
    open_loop : dict of str to StepResult
        Open loop (no feedback), unit reference step, at each point.
    frequencies : ndarray, shape (n_f,)
        Frequency axis of the Bode magnitudes, Hz.
    block_bode : dict of str to BodeResult
        Each component's Bode.
    closed_loop_bode : BodeResult
        The closed loop y/r.
    """

    time_s: np.ndarray
    reference: dict
    load: dict
    load_step: float
    t_load: float
    open_loop: dict
    frequencies: np.ndarray
    block_bode: dict
    closed_loop_bode: BodeResult


def block_schema_scenario(load_step: float = -0.5, t_load: float = 15.0, t_end: float = 40.0) -> BlockSchemaScenario:
    """The paper's block schema (:func:`~vibroscope.instruments.block_schema.paper_block_schema`)
    closed and open loop: a unit reference step, then a load step at the plant input; 6001 samples
    to `t_end`, Bode over 0.001-10 Hz (500 lines).

    Parameters
    ----------
    load_step : float, optional
        Height of the load step at the plant input (unit of r; default -0.5).
    t_load : float, optional
        Time of the load step, s (default 15).
    t_end : float, optional
        End of the time axis, s (default 40).

    Returns
    -------
    BlockSchemaScenario
    """
    t = np.linspace(0.0, t_end, 6001)
    cl = paper_block_schema(load=True)
    ol = paper_block_schema(load=False, closed=False)
    reference = {point: r.response for point, r in cl.step(t).items()}
    load = cl.forced_response(t, (t >= t_load).astype(float) * load_step, from_="d")
    f = np.logspace(-3, 1, 500)
    return BlockSchemaScenario(time_s=t, reference=reference, load=load, load_step=float(load_step),
                               t_load=float(t_load), open_loop=ol.step(t), frequencies=f,
                               block_bode=cl.block_bode(f), closed_loop_bode=bode(cl.transfer("y"), f))

