"""vibroscope: a virtual Fourier analyser for vibration logs.

Importing :mod:`vibroscope` never imports rerun, mcap or dask; those load lazily in
:mod:`vibroscope.io` and :mod:`vibroscope.viewers`.
"""

from vibroscope.errors import ChannelError, LogFormatError, ModelFileError, VibroscopeError
from vibroscope.signals import Signals

__version__ = "0.1.0"

__all__ = ["Signals", "VibroscopeError", "LogFormatError", "ChannelError", "ModelFileError", "__version__"]
