"""Cross-validation of a model against a measurement: per-mode frequency shifts between two sets
of FRF magnitudes (measured vs model), as in a model-updating report (Friswell & Mottershead,
Finite Element Model Updating in Structural Dynamics, 1995, ch. 1: the frequency residuals), and
the test-vs-model (or test-vs-test) comparison of two mode sets: frequency differences, the MAC
matrix and the paired modes (Allemang, "The Modal Assurance Criterion -- twenty years of use and
abuse", Sound and Vibration 37(8), 2003).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibroscope.modal._peaks import parabolic_peak
from vibroscope.modal.mac import mac, match_modes

__all__ = ["FrequencyShift", "resonance_peaks", "frequency_shift", "ModeSetComparison", "compare_mode_sets"]


@dataclass(frozen=True, kw_only=True)
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

    Returns
    -------
    FrequencyShift

    Notes
    -----
    Peaks below 1 % of the measured axis' top frequency are ignored (near 0 Hz a measured FRF is
    noise).
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
    return FrequencyShift(measured_hz=A, model_hz=B, shift_hz=B - A,
                          shift_relative=(B - A) / A if A.size else np.zeros(0),
                          unpaired_measured_hz=np.array([a for a in fa if a not in A]),
                          unpaired_model_hz=np.array([b for j, b in enumerate(fb) if j not in used]))


@dataclass(frozen=True, kw_only=True)
class ModeSetComparison:
    """Two mode sets compared: MAC matrix, paired modes and their frequency differences.

    Attributes
    ----------
    frequencies_a, frequencies_b : ndarray, shape (n_a,), (n_b,)
        Natural frequencies of each set in Hz, in the sets' own order.
    damping_a, damping_b : ndarray, shape (n_a,), (n_b,)
        Damping ratios (dimensionless; NaN where unknown).
    mac : ndarray, shape (n_a, n_b)
        MAC of every mode of A with every mode of B on the common `points`.
    pairs : ndarray of int, shape (n_pairs, 2)
        ``(index in A, index in B)``, sorted by the index in A.
    frequency_difference_hz : ndarray, shape (n_pairs,)
        ``f_B − f_A`` of each pair in Hz.
    frequency_difference : ndarray, shape (n_pairs,)
        ``(f_B − f_A) / f_A`` (dimensionless).
    mac_pairs : ndarray, shape (n_pairs,)
        MAC of each pair.
    unpaired_a, unpaired_b : ndarray of int
        Indices of the modes without a partner.
    points : tuple of str
        The points of A the MAC is computed on (matched to B by name, or by order, see
        `matched_by`).
    matched_by : str
        ``"name"`` or ``"order"``.
    labels : tuple of str
        Names of the two sets (e.g. the files).
    settings : dict
        ``mac_min``, ``max_frequency_error``, ``frequency_weight``.
    """

    frequencies_a: np.ndarray
    frequencies_b: np.ndarray
    damping_a: np.ndarray
    damping_b: np.ndarray
    mac: np.ndarray
    pairs: np.ndarray
    frequency_difference_hz: np.ndarray
    frequency_difference: np.ndarray
    mac_pairs: np.ndarray
    unpaired_a: np.ndarray
    unpaired_b: np.ndarray
    points: tuple
    matched_by: str
    labels: tuple = ("A", "B")
    settings: dict | None = None

    def __repr__(self) -> str:
        return (f"ModeSetComparison({len(self.pairs)} pairs of {self.frequencies_a.size} x "
                f"{self.frequencies_b.size} modes on {len(self.points)} points)")

    def to_dict(self) -> dict:
        """JSON-ready: ``{"labels", "points", "matched_by", "pairs": [{"a", "b", "frequency_a_hz",
        "frequency_b_hz", "difference_hz", "difference_percent", "mac", "damping_a", "damping_b"}],
        "unpaired_a", "unpaired_b", "mac", "settings"}`` (mode numbers 1-based, NaN as None)."""
        def num(v):
            v = float(v)
            return v if np.isfinite(v) else None

        pairs = [{"a": int(i) + 1, "b": int(j) + 1, "frequency_a_hz": float(self.frequencies_a[i]),
                  "frequency_b_hz": float(self.frequencies_b[j]), "difference_hz": float(d),
                  "difference_percent": float(100 * e), "mac": num(m),
                  "damping_a": num(self.damping_a[i]), "damping_b": num(self.damping_b[j])}
                 for (i, j), d, e, m in zip(self.pairs, self.frequency_difference_hz, self.frequency_difference,
                                            self.mac_pairs)]
        return {"labels": list(self.labels), "points": list(self.points), "matched_by": self.matched_by,
                "pairs": pairs,
                "unpaired_a": [{"mode": int(i) + 1, "frequency_hz": float(self.frequencies_a[i])} for i in self.unpaired_a],
                "unpaired_b": [{"mode": int(j) + 1, "frequency_hz": float(self.frequencies_b[j])} for j in self.unpaired_b],
                "mac": [[num(v) for v in row] for row in self.mac], "settings": dict(self.settings or {})}

    def plot(self, fig=None):
        """The MAC matrix and the frequency differences of the pairs
        (:func:`vibroscope.viewers.figures.plot_mode_set_comparison`).

        Parameters
        ----------
        fig : matplotlib.figure.Figure, optional

        Returns
        -------
        matplotlib.figure.Figure
        """
        from vibroscope._plotting import draw

        return draw("plot_mode_set_comparison", self, fig=fig)


def _common_points(a, b) -> tuple[list[int], list[int], str]:
    pa, pb = list(a.points), list(b.points)
    where = {p: k for k, p in enumerate(pb)}
    ia = [k for k, p in enumerate(pa) if p in where]
    if ia:
        return ia, [where[pa[k]] for k in ia], "name"
    if len(pa) == len(pb):
        return list(range(len(pa))), list(range(len(pb))), "order"
    raise ValueError(f"the mode sets share no point name and have {len(pa)} and {len(pb)} points: the MAC needs "
                     f"the same points (A: {pa[:4]}..., B: {pb[:4]}...)")


def compare_mode_sets(a, b, *, mac_min: float = 0.5, max_frequency_error: float = 0.5,
                      frequency_weight: float = 1.0, labels: tuple[str, str] = ("A", "B")) -> ModeSetComparison:
    """Compare two mode sets (test vs model, or two tests): MAC matrix, pairs, frequency differences.

    The modes are paired one-to-one by :func:`~vibroscope.modal.mac.match_modes` (minimum of
    ``Σ (1 − MAC) + w |f_A − f_B| / f_B``, Hungarian algorithm), whatever the order of either set;
    pairs with a MAC below `mac_min` or a relative frequency difference beyond
    `max_frequency_error` are left unpaired.

    Parameters
    ----------
    a, b : ModalModel
        Frequencies in Hz, complex shapes ``(n_modes, n_points)`` at ``points``. The MAC uses the
        points the two share by name (in A's order); when they share none but have as many
        points, the points are taken in order.
    mac_min : float, optional
        Smallest MAC of a pair (default 0.5).
    max_frequency_error : float, optional
        Largest ``|f_B − f_A| / f_A`` of a pair (default 0.5).
    frequency_weight : float, optional
        Weight ``w`` of the frequency distance in the pairing cost (default 1).
    labels : (str, str), optional
        Names of the two sets, for the report.

    Returns
    -------
    ModeSetComparison

    Raises
    ------
    ValueError
        If the sets share no point name and have different numbers of points, or one is empty.

    See Also
    --------
    vibroscope.modal.mac.match_modes : Pairs of an estimate with reference modes.
    frequency_shift : Shifts of resonance peaks between measured and model FRFs.

    References
    ----------
    .. [1] R. J. Allemang, "The Modal Assurance Criterion -- twenty years of use and abuse",
       Sound and Vibration 37(8), 14–23, 2003.

    Examples
    --------
    >>> from vibroscope.modal import ModalModel
    >>> a = ModalModel(natural_frequencies=[10.0, 20.0], damping_ratios=[0.01, 0.01],
    ...                shapes=[[1, 1], [1, -1]], points=["p", "q"], method="test")
    >>> b = ModalModel(natural_frequencies=[20.4, 10.1], damping_ratios=[0.01, 0.01],
    ...                shapes=[[1, -1], [1, 1]], points=["p", "q"], method="model")
    >>> c = compare_mode_sets(a, b)
    >>> c.pairs.tolist(), c.frequency_difference_hz.round(3).tolist()
    ([[0, 1], [1, 0]], [0.1, 0.4])
    """
    if not len(a) or not len(b):
        raise ValueError(f"a mode set is empty ({len(a)} and {len(b)} modes): nothing to compare")
    ia, ib, how = _common_points(a, b)
    sa = np.asarray(a.shapes)[:, ia]
    sb = np.asarray(b.shapes)[:, ib]
    fa, fb = np.asarray(a.natural_frequencies, float), np.asarray(b.natural_frequencies, float)
    M = mac(sa, sb)
    mm = match_modes((fa, sa), (fb, sb), mac_min=mac_min, frequency_weight=frequency_weight)
    pairs = np.asarray(mm.pairs, int).reshape(-1, 2)  # (index in A, index in B)
    keep = np.abs(fa[pairs[:, 0]] - fb[pairs[:, 1]]) <= max_frequency_error * fa[pairs[:, 0]]
    pairs = pairs[keep]
    pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
    d = fb[pairs[:, 1]] - fa[pairs[:, 0]]
    return ModeSetComparison(
        frequencies_a=fa, frequencies_b=fb, damping_a=np.asarray(a.damping_ratios, float),
        damping_b=np.asarray(b.damping_ratios, float), mac=M, pairs=pairs, frequency_difference_hz=d,
        frequency_difference=d / fa[pairs[:, 0]],
        mac_pairs=M[pairs[:, 0], pairs[:, 1]] if len(pairs) else np.zeros(0),
        unpaired_a=np.setdiff1d(np.arange(fa.size), pairs[:, 0]),
        unpaired_b=np.setdiff1d(np.arange(fb.size), pairs[:, 1]),
        points=tuple(a.points[k] for k in ia), matched_by=how, labels=tuple(labels),
        settings={"mac_min": mac_min, "max_frequency_error": max_frequency_error, "frequency_weight": frequency_weight})
