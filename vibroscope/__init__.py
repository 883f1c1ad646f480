"""vibroscope: a virtual Fourier analyser for vibration logs.

The names a script reaches for first are here, loaded on first use (PEP 562), so that
``import vibroscope`` stays light: it never imports rerun, matplotlib, mcap, dask, control or
numba; those load with the room that needs them (:mod:`vibroscope.io`, :mod:`vibroscope.viewers`,
:mod:`vibroscope.models`, ...).

- reading logs: :func:`read_mcap`; the in-memory container :class:`Signals`
- spectra and FRFs: :func:`welch`, :func:`csd_matrix`, :func:`frf`
- modal identification: :func:`lscf`, :func:`lsfd`, :func:`ssi_cov`, :func:`fdd`,
  :func:`peak_picking`, :func:`auto_ssi`, :func:`auto_lscf`
- models as ground truth: :func:`load_model`, :func:`simulate`
- sim-to-real gap: :func:`diagnose`

Examples
--------
>>> import numpy as np
>>> import vibroscope
>>> sig = vibroscope.Signals(data=np.zeros((1, 8)), fs=100.0, channels=["/imu.linear_acceleration.x"])
>>> sig.fs
100.0
"""

from __future__ import annotations

from vibroscope._lazy import lazy_attributes
from vibroscope.errors import ChannelError, LogFormatError, ModelFileError, VibroscopeError
from vibroscope.signals import Signals

__version__ = "0.1.0"

# name -> module that defines it; imported on first attribute access
_LAZY = {
    "read_mcap": "vibroscope.io",
    "welch": "vibroscope.spectral",
    "csd_matrix": "vibroscope.spectral",
    "frf": "vibroscope.spectral",
    "lscf": "vibroscope.modal",
    "lsfd": "vibroscope.modal",
    "ssi_cov": "vibroscope.modal",
    "fdd": "vibroscope.modal",
    "peak_picking": "vibroscope.modal",
    "auto_ssi": "vibroscope.modal",
    "auto_lscf": "vibroscope.modal",
    "load_model": "vibroscope.models.modelfile",
    "simulate": "vibroscope.models.simulate",
    "diagnose": "vibroscope.gap",
}

__all__ = [
    "Signals", "VibroscopeError", "LogFormatError", "ChannelError", "ModelFileError", "__version__",
    *_LAZY,
]


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY)
