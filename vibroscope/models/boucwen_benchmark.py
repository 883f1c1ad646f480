"""The Bouc-Wen hysteretic benchmark of Noël & Schoukens (2016): its model and its
simulation protocol.

References
----------
.. [1] J. P. Noël, M. Schoukens, "Hysteretic benchmark with a dynamic nonlinearity",
   Workshop on Nonlinear System Identification Benchmarks, Brussels, 2016.
"""

from __future__ import annotations

import numpy as np

from vibroscope.models.lumped import LumpedModel

__all__ = ["boucwen_benchmark_model", "simulate_boucwen_benchmark"]


def boucwen_benchmark_model(**params) -> LumpedModel:
    """The Bouc-Wen benchmark oscillator of Noël & Schoukens (2016).

    ``m y'' + k y + c y' + z = u``, ``z' = alpha y' - beta (gamma |y'| |z|^(nu-1) z +
    delta y' |z|^nu)`` with m = 2 kg, c = 10 N s/m, k = 5e4 N/m, alpha = 5e4 N/m,
    beta = 1e3 1/m, gamma = 0.8, delta = -1.1, nu = 1 (keyword arguments override the
    Bouc-Wen parameters). Input ``/actuator/force_cmd.wrench.force.x`` (N), output the
    displacement ``/sim/m.displacement.x`` (m).
    """
    from vibroscope.models.elements import BoucWen, Damper, Spring
    from vibroscope.models.lumped import Dof, Input, Output

    return LumpedModel(
        dofs=(Dof("m", 2.0),),
        elements=(
            Spring(("m", "ground"), k=5.0e4),
            Damper(("m", "ground"), c=10.0),
            BoucWen(("m", "ground"), **params),
        ),
        inputs=(Input(dof="m", channel="/actuator/force_cmd.wrench.force.x"),),
        outputs=(Output("m", "displacement", "/sim/m.displacement.x"),),
        name="Bouc-Wen benchmark",
    )


def simulate_boucwen_benchmark(
    u, *, fs: float = 750.0, periodic: bool = False, n_periods: int = 2, oversample: int = 20
) -> np.ndarray:
    """Displacement (m) of the Bouc-Wen benchmark for the force `u` (N) sampled at `fs`.

    Follows the benchmark's guidelines [1]_: integration at ``fs * oversample`` (15 kHz),
    band-limited upsampling of the input, MATLAB-style ``decimate(., 2/2/5, 'fir')`` of the
    output. ``periodic=True`` treats `u` as one period of a periodic input (FFT
    upsampling, `n_periods` simulated, last one returned); otherwise the simulation starts
    from rest (polyphase band-limited upsampling).

    Parameters
    ----------
    u : array_like, shape (n_samples,)
        Input force in N sampled at `fs` (with ``periodic=True``: one period).
    fs : float, optional
        Sampling frequency of `u` and of the result, Hz; default 750 (the benchmark's).
    periodic : bool, optional
        Treat `u` as one period of a periodic input and return the steady state
        (:func:`~vibroscope.models.simulate.simulate_periodic`); default False (from rest,
        :func:`~vibroscope.models.simulate.simulate`).
    n_periods : int, optional
        Periods simulated when `periodic`, the last one returned; default 2.
    oversample : int, optional
        Integration rate as a multiple of `fs`; default 20 (15 kHz at 750 Hz).

    Returns
    -------
    ndarray, shape (n_samples,)

    References
    ----------
    .. [1] J. P. Noël, M. Schoukens, "Hysteretic benchmark with a dynamic nonlinearity",
       Workshop on Nonlinear System Identification Benchmarks, Brussels, 2016.
    """
    from vibroscope.models.simulate import simulate, simulate_periodic

    model = boucwen_benchmark_model()
    if periodic:
        s = simulate_periodic(model, u, fs, n_periods=n_periods, oversample=oversample)
    else:
        s = simulate(model, u, fs, method="nonlinear", oversample=oversample)
    return s.data[1]
