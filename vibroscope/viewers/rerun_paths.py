"""Where the analysis goes in a rerun recording: entity paths of channels and modes, and the
frequency timeline of the spectra (see :mod:`vibroscope.viewers.rerun_view` for what the timelines
mean).

rerun is imported inside the functions: importing this module never imports it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["channel_entity", "mode_entity", "frequency_index", "frequency_timeline"]


def _esc(part: str) -> str:
    import rerun as rr

    return rr.escape_entity_path_part(part)


def channel_entity(prefix: str, channel: str) -> str:
    """Entity path of a channel under `prefix`: its message path split on ``/``, each part escaped.

    Parameters
    ----------
    prefix : str
        E.g. ``"signals"``, ``"psd"``, ``"frf/magnitude_db"``.
    channel : str
        Channel name, e.g. ``"/imu/wrist.linear_acceleration.z"``.

    Returns
    -------
    str
        E.g. ``"/signals/imu/wrist.linear_acceleration.z"`` (as rerun writes it back).
    """
    parts = [p for p in str(channel).split("/") if p] or ["_"]
    return "/" + "/".join([*(p for p in prefix.split("/") if p), *(_esc(p) for p in parts)])


def mode_entity(r: int, natural_frequency: float) -> str:
    """Entity path of mode `r` (0-based) at `natural_frequency` Hz: ``/modes/mode_1_2.82Hz``.

    Parameters
    ----------
    r : int
        Mode index from 0 (the path numbers modes from 1).
    natural_frequency : float
        Natural frequency in Hz (3 significant digits in the path).

    Returns
    -------
    str
    """
    return "/modes/" + _esc(f"mode_{r + 1}_{natural_frequency:.3g}Hz")


def frequency_index(frequencies: np.ndarray) -> tuple[str, np.ndarray]:
    """The frequency timeline used for spectra: its name and integer index values.

    Parameters
    ----------
    frequencies : array_like, shape (n_freqs,)
        Hz, ascending.

    Returns
    -------
    name : str
        ``"frequency_mHz"``, or ``"frequency_uHz"`` when mHz rounding would merge bins.
    index : ndarray of int64
        ``round(1000 f)`` (or ``round(1e6 f)``).
    """
    f = np.asarray(frequencies, dtype=float)
    idx = np.round(f * 1e3).astype(np.int64)
    if f.size > 1 and np.any(np.diff(idx) <= 0):
        return "frequency_uHz", np.round(f * 1e6).astype(np.int64)
    return "frequency_mHz", idx


def frequency_timeline(*results) -> tuple[str | None, np.ndarray | None]:
    """The frequency timeline (name, index) of the first of `results` that is given.

    Parameters
    ----------
    *results : Spectrum, CrossSpectralMatrix, FRF or None
        Results with ``frequencies`` (Hz); None for one not given.

    Returns
    -------
    name : str or None
        :func:`frequency_index` of the first given result; None when none is given.
    index : ndarray of int64 or None
        Its index values; None when none is given.
    """
    for src in results:
        if src is not None:
            return frequency_index(src.frequencies)
    return None, None
