"""Spectral analysis: Welch PSD, the cross-spectral matrix, amplitude spectrum, FRFs (H1, H2, Hv),
ordinary and multiple coherence, spectrogram — all from one cross-spectral engine with scipy's
conventions and parameter names. Imports nothing of vibroscope but :mod:`vibroscope.signals`.
"""

from vibroscope.spectral._engine import CrossSpectralAccumulator, segment_settings
from vibroscope.spectral._results import (
    FRF,
    FRF_KINDS,
    Coherence,
    CrossSpectralMatrix,
    MultipleCoherence,
    Spectrogram,
    Spectrum,
)
from vibroscope.spectral.estimators import (
    amplitude_spectrum,
    coherence,
    csd_matrix,
    frf,
    frf_kind,
    multiple_coherence,
    spectrogram,
    welch,
)
from vibroscope.spectral.integration import OperatingShape, Severity, integrate, ods, vibration_severity
from vibroscope.spectral.periodic import Periodicity, detect_period, frf_periodic

__all__ = [
    "welch", "csd_matrix", "amplitude_spectrum", "frf", "coherence", "multiple_coherence",
    "spectrogram", "frf_kind", "Spectrum", "CrossSpectralMatrix", "FRF", "Spectrogram", "FRF_KINDS",
    "Coherence", "MultipleCoherence",
    "CrossSpectralAccumulator", "segment_settings",
]
__all__ += ["integrate", "vibration_severity", "ods", "Severity", "OperatingShape"]
__all__ += ["detect_period", "frf_periodic", "Periodicity"]
