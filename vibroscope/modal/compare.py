"""Cross-validation of a model against a measurement: per-mode frequency shifts between two sets
of FRF magnitudes (measured vs model), as in a model-updating report (Friswell & Mottershead,
Finite Element Model Updating in Structural Dynamics, 1995, ch. 1: the frequency residuals).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibroscope.modal._peaks import parabolic_peak

__all__ = ["FrequencyShift", "resonance_peaks", "frequency_shift"]


@dataclass(frozen=True)
class FrequencyShift:
    """Resonances of a measurement and of a model, paired, and their shifts.

    Attributes
    ----------
    measured_hz, model_hz : ndarray, shape (n_pairs,)
        Paired resonance frequencies in Hz.
    shift_hz : ndarray, shape (n_pairs,)
        ``model − measured`` in Hz.
    shift_relative : ndarray, shape (n_pairs,)
        ``(model − measured) / measured`` (dimensionless).
    unpaired_measured_hz, unpaired_model_hz : ndarray
        Resonances without a partner within the pairing tolerance.
    """

    measured_hz: np.ndarray
    model_hz: np.ndarray
    shift_hz: np.ndarray
    shift_relative: np.ndarray
    unpaired_measured_hz: np.ndarray
    unpaired_model_hz: np.ndarray

    def __repr__(self) -> str:
        return (f"FrequencyShift({np.size(self.measured_hz)} pairs, {np.size(self.unpaired_measured_hz)} measured "
                f"and {np.size(self.unpaired_model_hz)} model resonances unpaired)")

    def to_dict(self) -> dict:
        """JSON-ready ``{"pairs": [{"measured_hz", "model_hz", "shift_hz", "shift_percent"}], ...}``."""
        return {"pairs": [{"measured_hz": float(a), "model_hz": float(b), "shift_hz": float(b - a),
                           "shift_percent": float(100 * (b - a) / a)} for a, b in zip(self.measured_hz, self.model_hz)],
                "unpaired_measured_hz": self.unpaired_measured_hz.tolist(),
                "unpaired_model_hz": self.unpaired_model_hz.tolist()}


def resonance_peaks(frequencies: np.ndarray, magnitude_db: np.ndarray, *, prominence: float = 15.0,
                    fmin: float | None = None) -> np.ndarray:
    """Resonance frequencies of FRF magnitudes: peaks of the summed power over the outputs.

    Parameters
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Axis in Hz.
    magnitude_db : ndarray, shape (n_freqs,) or (n_freqs, n_outputs)
        ``20 log10 |H|`` of each output.
    prominence : float, optional
        Smallest prominence (dB) of a peak of the summed power; default 15 dB.
    fmin : float, optional
        Lowest frequency considered (Hz); default the second line.

    Returns
    -------
    ndarray
        Peak frequencies in Hz, refined by a parabola through the peak line and its neighbours
        (on the dB curve).
    """
    import scipy.signal

    f = np.asarray(frequencies, float)
    m = np.asarray(magnitude_db, float).reshape(len(f), -1)
    p = 10 * np.log10(np.nansum(10 ** (m / 10), axis=1))
    lo = f[1] if fmin is None else fmin
    k0 = int(np.searchsorted(f, lo))
    pk, _ = scipy.signal.find_peaks(p[k0:], prominence=prominence)
    return np.array([parabolic_peak(f, p, k) for k in pk + k0], dtype=float)


def frequency_shift(measured: tuple[np.ndarray, np.ndarray], model: tuple[np.ndarray, np.ndarray], *,
                    prominence: float = 15.0, tolerance: float = 0.15) -> FrequencyShift:
    """Per-mode frequency shift between measured and model FRF magnitudes.

    Parameters
    ----------
    measured, model : (frequencies Hz, magnitude_db (n_freqs, n_outputs))
        The two sets of FRF magnitudes (same outputs, any axes).
    prominence : float, optional
        Peak prominence (dB) for :func:`resonance_peaks`; default 15 dB.
    tolerance : float, optional
        Largest relative distance of a pair; default 0.15.

    Notes
    -----
    Peaks below 1 % of the measured axis' top frequency are ignored (near 0 Hz a measured FRF is
    noise).

    Returns
    -------
    FrequencyShift
    """
    lo = 0.01 * float(np.max(measured[0]))  # the near-0 Hz lines of a measurement are noise
    fa = resonance_peaks(*measured, prominence=prominence, fmin=lo)
    fb = resonance_peaks(*model, prominence=prominence, fmin=lo)
    pairs, used = [], set()
    for a in fa:
        if not fb.size:
            break
        j = int(np.argmin(np.abs(fb - a)))
        if j not in used and abs(fb[j] / a - 1) <= tolerance:
            pairs.append((a, fb[j]))
            used.add(j)
    A = np.array([p[0] for p in pairs])
    B = np.array([p[1] for p in pairs])
    return FrequencyShift(A, B, B - A, (B - A) / A if A.size else np.zeros(0),
                          np.array([a for a in fa if a not in A]),
                          np.array([b for j, b in enumerate(fb) if j not in used]))
