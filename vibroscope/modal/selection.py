"""Physical-mode selection: which identified poles are modes of the structure, and why the others
are not.

Every identification method proposes candidates (clusters of stable poles for SSI-COV and LSCF,
peaks for peak picking and FDD). A candidate is reported as a mode only when it is

- **stable** across model orders (a cluster holding at least a quarter of the orders, for the
  methods with a stabilization diagram),
- **physically damped**: ``damping_range[0] ≤ ζ ≤ damping_range[1]`` (default 0.01 %–10 %:
  lighter than 0.01 % is a harmonic or an electrical line, heavier than 10 % is a noise or
  computational pole for the structures this tool is made for),
- **consistent in phase**: modal phase collinearity MPC ≥ `min_mpc` (default 0.5; Pappa et al.
  1993) — a lightly, proportionally damped structure has nearly real modes,
- **inside the band the test excites**: with a measured input, where the input's PSD is within
  20 dB of its maximum and the coherence at the mode is at least `min_coherence`; without one,
  inside the analysis band,
- **not a duplicate**: candidates closer in frequency than the spectra resolve (within
  `duplicate_bins` = 2 lines of the FRF/CSD: the half-width of the Hann window's main lobe, so
  two peaks nearer than that are one peak of the estimate) whose shapes agree (MAC ≥
  `duplicate_mac` = 0.9) are one mode. At a coarse resolution LSCF splits a lightly damped mode
  into two poles of the same model order that bracket it (the extra poles fit the noise of the
  few lines across the peak), and each of them forms its own stable cluster. A physical mode is
  one pole per model order -- the premise of the stabilization diagram -- so the candidate kept
  is the one whose cluster stands alone at the most orders (no duplicate has a pole at those
  orders), then the largest cluster, then the best MPC; the others are rejected as duplicates
  of it. This is the pole distance of Reynders et al. (2012) (frequency distance plus
  ``1 − MAC``) with the frequency tolerance set by the spectral resolution; two real close modes
  (different shapes, or farther apart than two lines) are kept.

The others are listed with the reason (:class:`RejectedMode`), so that an engineer can see what
was dropped. This is the automated scheme of Reynders, Houbrechts & De Roeck (2012) and
Magalhães, Cunha & Caetano (2009) reduced to criteria that need no user tuning.

References
----------
.. [1] E. Reynders, J. Houbrechts and G. De Roeck, "Fully automated (operational) modal
   analysis", Mechanical Systems and Signal Processing 29, 228–250, 2012.
.. [2] F. Magalhães, Á. Cunha and E. Caetano, "Online automatic identification of the modal
   parameters of a long span arch bridge", Mechanical Systems and Signal Processing 23(2),
   316–329, 2009.
.. [3] R. S. Pappa, K. B. Elliott and A. Schenk, "Consistent-mode indicator for the eigensystem
   realization algorithm", J. Guidance, Control, and Dynamics 16(5), 852–858, 1993.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from vibroscope.modal._peaks import MIN_BAND_LINES  # public here: the fewest lines a band must hold for a peak search
from vibroscope.modal._results import ModalModel, mpc, normalize_shapes
from vibroscope.modal.mac import mac

__all__ = ["RejectedMode", "Selection", "select_modes", "cluster_poles", "pick_poles", "excited_band", "response_band",
           "DAMPING_RANGE", "MIN_MPC", "DUPLICATE_BINS", "DUPLICATE_MAC", "MIN_BAND_LINES"]

#: physically plausible viscous damping ratios (dimensionless) of a structural mode
DAMPING_RANGE = (1e-4, 0.10)
#: smallest modal phase collinearity of a reported mode
MIN_MPC = 0.5
#: candidates within this many spectral lines of each other (and with similar shapes) are one mode
DUPLICATE_BINS = 2.0
#: smallest MAC between two candidates within :data:`DUPLICATE_BINS` lines that makes them one mode
DUPLICATE_MAC = 0.9


@dataclass(frozen=True)
class RejectedMode:
    """A candidate that was not reported as a mode.

    Attributes
    ----------
    natural_frequency : float
        Its natural frequency in Hz (the JSON key is ``frequency_hz``).
    damping_ratio : float
        Its damping ratio (dimensionless); NaN when not estimated.
    reason : str
        Why it was rejected, with the value and the threshold.
    """

    natural_frequency: float
    damping_ratio: float
    reason: str

    def to_dict(self) -> dict:
        """``{"frequency_hz", "damping_ratio", "reason"}`` (NaN damping as None)."""
        z = self.damping_ratio
        return {"frequency_hz": float(self.natural_frequency),
                "damping_ratio": None if not np.isfinite(z) else float(z), "reason": self.reason}


@dataclass(frozen=True, eq=False)
class Selection:
    """The modes kept by :func:`select_modes` and the candidates rejected.

    Attributes
    ----------
    modes : ModalModel
        The physical modes.
    rejected : tuple of RejectedMode
        The rest, ascending in frequency, each with its reason.
    criteria : dict
        The thresholds applied (``damping_range``, ``min_mpc``, ``band_hz``, ...).
    """

    modes: ModalModel
    rejected: tuple = ()
    criteria: dict = field(default_factory=dict)

    def __iter__(self):
        return iter((self.modes, self.rejected))

    def __repr__(self) -> str:
        return f"Selection({self.modes!r}, {len(self.rejected)} rejected)"


def subset_modes(model: ModalModel, keep: np.ndarray) -> ModalModel:
    """The modes `keep` (indices) of `model`, with every per-mode ``extra`` array subset too."""
    keep = np.asarray(keep, dtype=int)
    n = len(model)
    extra = {}
    for k, v in model.extra.items():
        if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == n:
            extra[k] = v[keep]
        else:
            extra[k] = v
    return ModalModel(natural_frequencies=model.natural_frequencies[keep], damping_ratios=model.damping_ratios[keep],
                      shapes=model.shapes[keep] if n else model.shapes, points=model.points, method=model.method,
                      extra=extra)


def excited_band(frequencies: np.ndarray, input_psd: np.ndarray, *, drop_db: float = 20.0,
                 smooth: int = 1) -> tuple[float, float]:
    """The band a measured input excites: where its PSD is within `drop_db` of its maximum.

    Parameters
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Frequency axis in Hz.
    input_psd : ndarray, shape (n_freqs,)
        PSD of the input (unit²/Hz).
    drop_db : float, optional
        Level below the maximum (dB) that still counts as excited; default 20 dB (a hammer test's
        usual −10 to −20 dB roll-off criterion, Ewins 2000 §3.6); the gap diagnosis passes 30 dB
        (:func:`vibroscope.gap.measure.excited_band`).
    smooth : int, optional
        Lines of a centred moving average taken before the threshold, the PSD kept where it is
        higher (so a line is never lowered and a lone line widens to its neighbours); default 1:
        none.

    Returns
    -------
    (fmin, fmax) : tuple of float
        The lowest and highest frequency (Hz) at which the input PSD is within `drop_db` of its
        maximum (the 0 Hz line excluded).

    Raises
    ------
    ValueError
        If the input PSD has no positive value.
    """
    f = np.asarray(frequencies, float)
    p = np.asarray(input_psd, float)
    if smooth > 1:
        p = np.maximum(np.convolve(p, np.ones(smooth) / smooth, mode="same"), p)
    m = (f > 0) & np.isfinite(p)
    if not np.any(p[m] > 0):
        raise ValueError("the input PSD is zero everywhere: the input excites nothing")
    top = np.max(p[m])
    ok = m & (p >= top * 10 ** (-drop_db / 10))
    return float(f[ok].min()), float(f[ok].max())


def response_band(frequencies: np.ndarray, psd: np.ndarray, *, energy: float = 0.95,
                  fmin: float | None = None) -> tuple[float, float]:
    """The band of an output-only record's vibration: its lowest resonance and the frequency
    below which `energy` of the response variance lies.

    Parameters
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Frequency axis in Hz (Welch).
    psd : ndarray, shape (n_freqs,) or (n_channels, n_freqs)
        PSD (unit²/Hz) of the responses; several channels are summed.
    energy : float, optional
        Fraction of the summed variance below the upper limit; default 0.95 (the rest is the
        broadband floor of the sensors and the ambient excitation, where no clear mode stands).
    fmin : float, optional
        Lowest frequency considered (Hz); default ten Welch lines.

    Returns
    -------
    (f_low, fmax) : tuple of float
        `f_low`: the lowest spectral peak (prominence ≥ 10 dB) above `fmin` — the lowest mode,
        whose period sets the covariance lags of SSI-COV; `fmax`: the `energy` limit in Hz.
    """
    import scipy.signal

    f = np.asarray(frequencies, float)
    p = np.nan_to_num(np.atleast_2d(np.asarray(psd, float)), nan=0.0).sum(axis=0)
    df = f[1] - f[0]
    lo = min(10 * df, f[len(f) // 8]) if fmin is None else max(float(fmin), df)
    m = f >= lo
    if m.sum() < 3 or not np.any(p[m] > 0):
        return float(max(lo, df)), float(f[-1])
    c = np.cumsum(p[m])
    fmax = float(f[m][min(int(np.searchsorted(c, energy * c[-1])), m.sum() - 1)])
    band = m & (f <= fmax)
    db = 10 * np.log10(np.maximum(p[band], np.finfo(float).tiny))
    pk, _ = scipy.signal.find_peaks(db, prominence=10.0)
    f_low = float(f[band][pk[0]]) if pk.size else lo
    return f_low, max(fmax, 2 * f_low)


def cluster_poles(stabilization, *, min_count: int | None = None, tol_frequency: float = 0.01, mac_min: float = 0.9,
                  fmin: float | None = None, fmax: float | None = None) -> tuple[ModalModel, list[RejectedMode]]:
    """Modes as clusters of fully stable poles of a stabilization diagram.

    Fully stable poles (``stable == 3``) are taken by increasing frequency and grouped while within
    `tol_frequency` (relative) of the cluster's median frequency and with MAC ≥ `mac_min` to its first
    member. A cluster with at least `min_count` poles is a mode (median frequency and damping, the
    shape of the member nearest the median frequency); smaller clusters of two or more poles are
    returned as rejected ("stable in k of N orders"). Magalhães et al. (2009) cluster the same way.

    Parameters
    ----------
    stabilization : Stabilization
        From :func:`vibroscope.modal.ssi_cov` or :func:`vibroscope.modal.lscf`.
    min_count : int, optional
        Smallest cluster; default ``max(3, n_orders // 4)``.
    tol_frequency : float, optional
        Relative frequency tolerance of a cluster; default 0.01.
    mac_min : float, optional
        Smallest MAC with the cluster's first pole; default 0.9.
    fmin, fmax : float, optional
        Band in Hz.

    Returns
    -------
    (ModalModel, list of RejectedMode)
        ``extra``: ``cluster_size``, ``damping_std`` and ``frequency_std_hz`` (spread over the
        cluster's orders, not a statistical uncertainty), ``mpc``, ``order`` (of the
        representative pole), ``cluster_orders`` (object array of frozensets: the model orders
        of each cluster's poles, which :func:`select_modes` uses to tell a split mode from the
        mode) and ``settings`` (the diagram's, with ``min_count``, ``cluster_tol_frequency``
        (this `tol_frequency`; the diagram's own ``tol_frequency`` is its stability criterion)
        and ``mac_min``).
    """
    st = stabilization
    n_orders = len(st.settings.get("orders", ())) or int(np.unique(st.order).size)
    min_count = max(3, n_orders // 4) if min_count is None else int(min_count)
    method = st.settings.get("method", "ssi_cov")
    sel = st.stable == 3
    if fmin is not None:
        sel &= st.frequency >= fmin
    if fmax is not None:
        sel &= st.frequency <= fmax
    idx = np.flatnonzero(sel)
    idx = idx[np.argsort(st.frequency[idx], kind="stable")]
    used = np.zeros(len(idx), bool)
    modes, rejected = [], []
    for a in range(len(idx)):
        if used[a]:
            continue
        members = [a]
        f0 = st.frequency[idx[a]]
        for b in range(a + 1, len(idx)):
            if used[b]:
                continue
            fb = st.frequency[idx[b]]
            if fb > f0 * (1 + 2 * tol_frequency):
                break
            fmed = np.median(st.frequency[idx[members]])
            if abs(fb / fmed - 1) <= tol_frequency and mac(st.shapes[idx[a]], st.shapes[idx[b]])[0, 0] >= mac_min:
                members.append(b)
        p = idx[members]
        fmed = float(np.median(st.frequency[p]))
        if len(members) >= min_count:
            used[members] = True
            rep = p[np.argmin(np.abs(st.frequency[p] - fmed))]
            modes.append((fmed, float(np.median(st.damping[p])), st.shapes[rep], len(p),
                          float(np.std(st.damping[p])), float(np.std(st.frequency[p])), int(st.order[rep]),
                          frozenset(int(o) for o in st.order[p])))
        elif len(members) >= 2:
            used[members] = True
            rejected.append(RejectedMode(fmed, float(np.median(st.damping[p])),
                                         f"not stable across orders: {len(p)} of {n_orders} orders (< {min_count})"))
    settings = dict(st.settings, min_count=min_count, cluster_tol_frequency=tol_frequency, mac_min=mac_min)
    if not modes:
        empty = np.zeros(0)
        return ModalModel(natural_frequencies=empty, damping_ratios=empty, shapes=np.zeros((0, len(st.points))),
                          points=st.points, method=method,
                          extra={"cluster_size": np.zeros(0, int), "damping_std": empty, "frequency_std_hz": empty,
                           "mpc": empty, "order": np.zeros(0, int), "cluster_orders": np.empty(0, object),
                           "settings": settings}), rejected
    f, z, s, c, zs, fsd, o, co = zip(*modes)
    shapes = normalize_shapes(np.array(s))
    orders = np.empty(len(co), object)
    orders[:] = co
    return ModalModel(natural_frequencies=np.array(f), damping_ratios=np.array(z), shapes=shapes, points=st.points,
                      method=method,
                      extra={"cluster_size": np.array(c), "damping_std": np.array(zs),
                             "frequency_std_hz": np.array(fsd),
                       "mpc": mpc(shapes), "order": np.array(o), "cluster_orders": orders,
                       "settings": settings}), rejected


def select_modes(
    model: ModalModel,
    *,
    fmin: float | None = None,
    fmax: float | None = None,
    damping_range: tuple[float, float] = DAMPING_RANGE,
    min_mpc: float = MIN_MPC,
    coherence: tuple[np.ndarray, np.ndarray] | None = None,
    min_coherence: float = 0.5,
    rejected: Sequence[RejectedMode] = (),
    resolution_hz: float | None = None,
    duplicate_bins: float = DUPLICATE_BINS,
    duplicate_mac: float = DUPLICATE_MAC,
) -> Selection:
    """Keep the physical modes of an identified model; list the others with the reason.

    Parameters
    ----------
    model : ModalModel
        Candidates from any method.
    fmin, fmax : float, optional
        The band that was excited (Hz): the input's band (see :func:`excited_band`) with a
        measured input, the analysis band without.
    damping_range : (float, float), optional
        Physically plausible damping ratios; default :data:`DAMPING_RANGE` (0.01 %–10 %). A NaN
        damping (not estimated) is not a reason to reject.
    min_mpc : float, optional
        Smallest modal phase collinearity; default :data:`MIN_MPC` (0.5). Skipped for one point.
    coherence : (frequencies, gamma2), optional
        Axis (Hz) and coherence, shape (n_freqs,) or (n_freqs, n_outputs); a mode needs
        `min_coherence` at its frequency on at least one output.
    min_coherence : float, optional
        Default 0.5.
    rejected : sequence of RejectedMode, optional
        Candidates already rejected upstream (e.g. unstable clusters); carried into the result.
    resolution_hz : float, optional
        Line spacing (Hz) of the spectra the candidates were identified from (FRF or CSD). With
        it, candidates that pass the criteria above but lie within ``duplicate_bins ·
        resolution_hz`` of each other with MAC ≥ `duplicate_mac` are one mode: the one whose
        cluster stands alone at the most model orders (``extra["cluster_orders"]``), then the
        largest cluster (``extra["cluster_size"]``), then the best MPC is kept and the others are
        rejected as its duplicates (see the module notes). Default None: no merging.
    duplicate_bins : float, optional
        Frequency tolerance in lines of `resolution_hz`; default :data:`DUPLICATE_BINS` (2).
    duplicate_mac : float, optional
        Smallest MAC of duplicates; default :data:`DUPLICATE_MAC` (0.9).

    Returns
    -------
    Selection
        ``modes`` ascending in frequency with ``extra["stable"]`` True, ``rejected`` with reasons.

    Raises
    ------
    ValueError
        If `resolution_hz` is given and is not a positive, finite number.
    """
    f = model.natural_frequencies
    z = model.damping_ratios
    m = mpc(model.shapes) if len(model) else np.zeros(0)
    out = list(rejected)
    keep = []
    for r in range(len(model)):
        why = None
        if fmin is not None and f[r] < fmin:
            why = f"below the band ({f[r]:.4g} < {fmin:.4g} Hz)"
        elif fmax is not None and f[r] > fmax:
            why = f"above the band ({f[r]:.4g} > {fmax:.4g} Hz)"
        elif np.isfinite(z[r]) and not (damping_range[0] <= z[r] <= damping_range[1]):
            why = (f"damping {100 * z[r]:.3g} % outside the physical range "
                   f"{100 * damping_range[0]:.3g}–{100 * damping_range[1]:.3g} %")
        elif len(model.points) > 1 and np.isfinite(m[r]) and m[r] < min_mpc:
            why = f"complex shape: MPC {m[r]:.2f} < {min_mpc:g}"
        elif coherence is not None:
            fc, g = coherence
            g = np.asarray(g, float).reshape(len(fc), -1)
            k = int(np.argmin(np.abs(np.asarray(fc) - f[r])))
            gk = np.nanmax(g[k]) if np.any(np.isfinite(g[k])) else np.nan
            if np.isfinite(gk) and gk < min_coherence:
                why = f"coherence {gk:.2f} < {min_coherence:g} at the mode"
        if why is None:
            keep.append(r)
        else:
            out.append(RejectedMode(float(f[r]), float(z[r]), why))
    duplicate = None
    if resolution_hz is not None:
        if not (np.isfinite(resolution_hz) and resolution_hz > 0):
            raise ValueError(f"{resolution_hz=} Hz must be a positive, finite line spacing")
        keep, dups = _drop_duplicates(model, keep, float(resolution_hz), duplicate_bins, duplicate_mac, m)
        out += dups
        duplicate = {"resolution_hz": float(resolution_hz), "bins": duplicate_bins, "mac_min": duplicate_mac}
    kept = subset_modes(model, np.array(keep, dtype=int))
    kept = dataclasses.replace(kept, extra={**kept.extra, "stable": np.ones(len(kept), bool)})
    out.sort(key=lambda x: x.natural_frequency)
    criteria = {"band_hz": [fmin, fmax], "damping_range": list(damping_range), "min_mpc": min_mpc,
                "min_coherence": min_coherence if coherence is not None else None, "duplicates": duplicate}
    return Selection(kept, tuple(out), criteria)


def _drop_duplicates(model: ModalModel, keep: list, df: float, bins: float, mac_min: float,
                     m: np.ndarray) -> tuple[list, list]:
    """Candidates `keep` (indices into `model`) without duplicates: (kept indices ascending, rejected).

    Two candidates are duplicates when within `bins` lines of `df` Hz and with MAC ≥ `mac_min`.
    Candidates are ranked by the model orders at which their cluster stands alone (no duplicate
    has a pole there), then cluster size, then MPC `m`; each in turn is kept unless a duplicate of
    one already kept (a greedy suppression: the best-supported candidate of a group survives).
    """
    if len(keep) < 2:
        return list(keep), []
    tol_hz = bins * df
    idx = np.asarray(keep, dtype=int)
    f = model.natural_frequencies[idx]
    z = model.damping_ratios[idx]
    M = mac(model.shapes[idx], model.shapes[idx])
    near = (np.abs(f[:, None] - f[None, :]) <= tol_hz) & (M >= mac_min)
    np.fill_diagonal(near, False)
    if not near.any():
        return list(keep), []
    ex = model.extra
    n = len(model)

    def per_mode(key):
        v = ex.get(key)
        return v[idx] if isinstance(v, np.ndarray) and v.shape[:1] == (n,) else None

    orders, size = per_mode("cluster_orders"), per_mode("cluster_size")
    lone = np.zeros(len(idx), int)
    if orders is not None:
        for i in range(len(idx)):
            others = set().union(*(orders[j] for j in np.flatnonzero(near[i])))
            lone[i] = len(set(orders[i]) - others)
    size = np.zeros(len(idx), int) if size is None else np.asarray(size, int)
    q = np.nan_to_num(np.asarray(m, float)[idx], nan=0.0) if len(m) else np.zeros(len(idx))
    ranked = sorted(range(len(idx)), key=lambda i: (lone[i], size[i], q[i]), reverse=True)
    kept_local, rejected = [], []
    for i in ranked:
        twin = next((j for j in kept_local if near[i, j]), None)
        if twin is None:
            kept_local.append(i)
            continue
        if lone[twin] > lone[i]:
            support = f"; {f[twin]:.5g} Hz is the group's only pole at {lone[twin]} model orders, this one at {lone[i]}"
        elif size[twin] > size[i]:
            support = f"; {f[twin]:.5g} Hz has the larger cluster ({size[twin]} poles against {size[i]})"
        else:
            support = f"; {f[twin]:.5g} Hz has the better MPC ({q[twin]:.3f} against {q[i]:.3f})"
        rejected.append(RejectedMode(float(f[i]), float(z[i]),
                                     f"duplicate of {f[twin]:.5g} Hz: {abs(f[i] - f[twin]):.3g} Hz apart, within "
                                     f"{bins:g} lines of {df:.4g} Hz (not separable), MAC {M[i, twin]:.3f}"
                                     f"{support}"))
    return sorted(int(idx[i]) for i in kept_local), rejected


def pick_poles(stabilization, natural_frequencies: Sequence[float], *, search: float = 0.05,
               tol_frequency: float = 0.01) -> ModalModel:
    """Modes at chosen frequencies of a stabilization diagram (the engineer's pick).

    For each requested frequency the nearest pole that is stable in frequency and damping
    (``stable >= 2``, else any pole) within ±`search` (relative) is found; the poles within
    `tol_frequency` of it with the same or better stability form its cluster (median frequency and
    damping, the shape of the highest-order member).

    Parameters
    ----------
    stabilization : Stabilization
    natural_frequencies : sequence of float
        Requested natural frequencies in Hz.
    search : float, optional
        Relative search window; default 0.05.
    tol_frequency : float, optional
        Relative cluster width; default 0.01.

    Returns
    -------
    ModalModel
        One mode per requested frequency, ascending; ``extra["requested_hz"]``.

    Raises
    ------
    ValueError
        If no pole lies within the search window of a requested frequency.
    """
    st = stabilization
    rows = []
    for fr in natural_frequencies:
        near = np.abs(st.frequency / fr - 1) <= search
        if not near.any():
            raise ValueError(f"no pole within {100 * search:g} % of {fr:g} Hz in the stabilization diagram")
        best = near & (st.stable >= 2) if np.any(near & (st.stable >= 2)) else near
        k = np.flatnonzero(best)[np.argmin(np.abs(st.frequency[best] - fr))]
        memb = best & (np.abs(st.frequency / st.frequency[k] - 1) <= tol_frequency)
        p = np.flatnonzero(memb)
        rep = p[np.argmax(st.order[p])]
        rows.append((float(np.median(st.frequency[p])), float(np.median(st.damping[p])), st.shapes[rep],
                     int(st.order[rep]), float(fr), float(np.std(st.frequency[p])), float(np.std(st.damping[p]))))
    rows.sort(key=lambda r: r[0])
    f, z, sh, o, req, fsd, zsd = zip(*rows)
    shapes = normalize_shapes(np.array(sh))
    return ModalModel(natural_frequencies=np.array(f), damping_ratios=np.array(z), shapes=shapes, points=st.points,
                      method=st.settings.get("method", "ssi_cov"),
                      extra={"order": np.array(o), "requested_hz": np.array(req), "frequency_std_hz": np.array(fsd),
                       "damping_std": np.array(zsd), "mpc": mpc(shapes), "stable": np.ones(len(rows), bool)})
