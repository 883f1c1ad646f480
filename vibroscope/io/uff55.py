"""UFF dataset 55 (Data at Nodes): mode shapes written as complex eigenvalue records
(:func:`write_modes_uff55`) and read from normal-mode and complex eigenvalue records
(:func:`read_modes_uff55`), through pyuff.

References
----------
.. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 55
   (Data at Nodes),
   University of Cincinnati.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from vibroscope.errors import LogFormatError
from vibroscope.io.uff import (
    AXIS,
    dataset_summary,
    date_line,
    dof_name,
    id_line,
    open_uff,
    parse_dof,
    read_label,
    read_set,
    remove_existing,
)
from vibroscope.modal import ModalModel

__all__ = ["write_modes_uff55", "read_modes_uff55"]

def _direction_code(v: Any, k: int) -> int:
    if isinstance(v, (int, np.integer)):
        code = int(v)
    else:
        s = str(v).strip().upper()
        sign = -1 if s.startswith("-") else 1
        s = s.lstrip("+-").strip()
        code = sign * ({"X": 1, "Y": 2, "Z": 3, "1": 1, "2": 2, "3": 3}.get(s, 0))
    if abs(code) not in (1, 2, 3):
        raise ValueError(f"directions[{k}]={v!r} must be one of ±1, ±2, ±3 or '+X', '-y', 'z', ...")
    return code


def write_modes_uff55(
    modal_model: ModalModel,
    path: str | Path,
    *,
    node_ids: Sequence[int] | None = None,
    directions: Sequence[int | str] | None = None,
) -> Path:
    """Write mode shapes as UFF dataset 55 records (complex eigenvalue, one per mode).

    Parameters
    ----------
    modal_model : ModalModel
        Natural frequencies (Hz), damping ratios and complex shapes (n_modes, n_points).
    path : str or Path
        The file to write (overwritten).
    node_ids : sequence of int, optional
        The node of each point, shape (n_points,). Default: from a point name that reads as a
        node DOF (``"12+Z"``, ``"12"``), else ``k + 1`` for the k-th point.
    directions : sequence of int or str, optional
        The measuring direction of each point, shape (n_points,): ``±1/±2/±3`` or ``'+X'``,
        ``'-y'``, ``'z'``. Default: from a DOF-like point name, else ``+Z``.

    Returns
    -------
    Path
        `path`.

    Raises
    ------
    ValueError
        If `node_ids`/`directions` have the wrong length or two points share a node DOF, or a
        damping ratio is not in (-1, 1).

    See Also
    --------
    read_modes_uff55 : Read the records back.

    Notes
    -----
    Each mode is one record of analysis type 3 (complex eigenvalue, first order), data
    characteristic 2 (3-DOF translation), specific data type 8 (displacement), complex data.
    The eigenvalue (rad/s) is ``λ = -ζ ω + j ω √(1-ζ²)`` with ``ω = 2π f_n``, so the natural
    frequency ``|λ|/2π`` and the damping ratio ``-Re λ / |λ|`` survive; an unknown (NaN) damping
    ratio is written as a NaN real part with ``Im λ = ω``. A point's shape value goes to its
    node's X/Y/Z slot, negated for a negative direction; the other slots are 0. Modal A and B
    are written as 0. ID line 1 holds the model's method. All values are written with 6
    significant digits (``E13.5``).

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 55
       (Data at Nodes), University of Cincinnati.
    """
    import pyuff

    path = Path(path)
    n_pts = len(modal_model.points)
    parsed = [parse_dof(p) for p in modal_model.points]
    if node_ids is None:
        nodes = [p[0] if p else k + 1 for k, p in enumerate(parsed)]
    else:
        nodes = [int(n) for n in node_ids]
        if len(nodes) != n_pts:
            raise ValueError(f"{len(nodes)} node_ids for {n_pts} points")
    if directions is None:
        dirs = [p[1] if (p and p[1] and abs(p[1]) <= 3) else 3 for p in parsed]
    else:
        if len(directions) != n_pts:
            raise ValueError(f"{len(directions)} directions for {n_pts} points")
        dirs = [_direction_code(v, k) for k, v in enumerate(directions)]
    seen: dict[tuple[int, int], str] = {}
    for p, nd, dr in zip(modal_model.points, nodes, dirs):
        if (nd, abs(dr)) in seen:
            raise ValueError(f"points {seen[(nd, abs(dr))]!r} and {p!r} share node {nd} direction {AXIS[abs(dr)]}")
        seen[(nd, abs(dr))] = p
    uniq = list(dict.fromkeys(nodes))
    pos = {nd: k for k, nd in enumerate(uniq)}
    dsets = []
    for m in range(len(modal_model)):
        fn = float(modal_model.natural_frequencies[m])
        z = float(modal_model.damping_ratios[m])
        w = 2 * np.pi * fn
        if np.isnan(z):
            eig = complex(np.nan, w)
        else:
            if not -1 < z < 1:
                raise ValueError(f"mode {m + 1}: damping ratio {z} must be in (-1, 1) for a complex eigenvalue")
            eig = complex(-z * w, w * np.sqrt(1 - z * z))
        r = np.zeros((3, len(uniq)), complex)
        for k, (nd, dr) in enumerate(zip(nodes, dirs)):
            r[abs(dr) - 1, pos[nd]] = np.sign(dr) * modal_model.shapes[m, k]
        ds = pyuff.prepare_55(
            id1=id_line(modal_model.method), id2=id_line("vibroscope mode shapes"), id3=id_line(date_line()),
            id4="NONE", id5=id_line(f"Mode {m + 1} {fn:.6g} Hz"),
            model_type=1, analysis_type=3, data_ch=2, spec_data_type=8, data_type=5, n_data_per_node=3,
            r1=r[0], r2=r[1], r3=r[2], load_case=1, mode_n=m + 1, eig=eig, modal_a=0j, modal_b=0j,
            node_nums=np.asarray(uniq, dtype=int))
        dsets.append(ds)
    if not dsets:
        raise ValueError("the modal model has no modes: nothing to write")
    remove_existing(path)
    pyuff.UFF(str(path)).write_sets(dsets, mode="add")
    return path


def read_modes_uff55(path: str | Path) -> ModalModel:
    """Read mode shapes from UFF dataset 55 records.

    Parameters
    ----------
    path : str or Path
        A Universal File holding dataset-55 records of analysis type 2 (normal mode), 3 or 7
        (complex eigenvalue, first or second order); other datasets and analysis types
        (frequency response, static) are skipped.

    Returns
    -------
    ModalModel
        One mode per record, in file order. Complex eigenvalue records give the natural
        frequency ``|λ|/2π`` (Hz) and damping ratio ``-Re λ / |λ|`` (a NaN real part:
        frequency ``Im λ / 2π``, damping NaN); normal-mode records their frequency and modal
        viscous damping ratio. Points are the node DOFs ``"{node}+X|Y|Z"`` (and ``+RX..RZ`` for
        6-DOF real data) that are nonzero in at least one mode, in node order of appearance;
        a node absent from a record counts as 0 (dataset-55 note 9). Shapes are as stored (not
        renormalised). `method` is ID line 1 of the first record (``"uff55"`` when NONE);
        `extra` holds ``mode_numbers``, ``analysis_types`` (arrays, one per mode), ``modal_a``,
        ``modal_b`` (complex eigenvalue records; NaN otherwise) and ``source``.

    Raises
    ------
    LogFormatError
        If the file is unreadable or holds no mode record (names the datasets and analysis
        types found).

    See Also
    --------
    write_modes_uff55 : Write mode shapes as UFF dataset 55 records.
    vibroscope.io.read_mode_set : A set of modes from a UFF 55 file, a model file or a MODES.json.

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 55
       (Data at Nodes), University of Cincinnati.
    """
    path = Path(path)
    u, types = open_uff(path)
    recs, found = [], []
    for i, t in enumerate(types):
        if t != 55:
            continue
        s = read_set(u, path, i)
        at = int(s.get("analysis_type", 0))
        found.append(at)
        if at in (2, 3, 7):
            recs.append((i, s))
    if not recs:
        raise LogFormatError(f"{path}: no UFF 55 mode record (analysis type 2, 3 or 7) among {len(types)} data "
                             f"sets ({dataset_summary(types)}); dataset-55 analysis types found: {sorted(set(found))}")
    freqs, zetas, mode_n, ats, ma, mb = [], [], [], [], [], []
    values: list[dict[tuple[int, int], complex]] = []
    dof_order: list[tuple[int, int]] = []
    for i, s in recs:
        at = int(s["analysis_type"])
        if at == 2:
            fn = float(s.get("freq", np.nan))
            z = float(s.get("modal_damp_vis", np.nan))
            ma.append(np.nan)
            mb.append(np.nan)
        else:
            lam = complex(s.get("eig", np.nan))
            if np.isnan(lam.real):
                fn, z = lam.imag / (2 * np.pi), np.nan
            else:
                wn = abs(lam)
                fn = wn / (2 * np.pi)
                z = -lam.real / wn if wn > 0 else np.nan
            ma.append(complex(s.get("modal_a", np.nan)))
            mb.append(complex(s.get("modal_b", np.nan)))
        freqs.append(fn)
        zetas.append(z)
        mode_n.append(int(s.get("mode_n", len(freqs))))
        ats.append(at)
        nodes = np.asarray(s.get("node_nums", []), int)
        comps = [s[k] for k in ("r1", "r2", "r3", "r4", "r5", "r6") if k in s]
        if any(len(c) != nodes.size for c in comps):
            raise LogFormatError(f"{path}: data set #{i + 1}: {nodes.size} nodes but value arrays of lengths "
                                 f"{[len(c) for c in comps]}")
        vals: dict[tuple[int, int], complex] = {}
        for j, nd in enumerate(nodes):
            for c, comp in enumerate(comps, start=1):
                key = (int(nd), c)
                vals[key] = complex(comp[j])
                if key not in dof_order:
                    dof_order.append(key)
        values.append(vals)
    nonzero = [k for k in dof_order if any(v.get(k, 0) != 0 for v in values)]
    shapes = np.array([[v.get(k, 0j) for k in nonzero] for v in values], complex).reshape(len(values), len(nonzero))
    method = read_label(recs[0][1].get("id1")) or "uff55"
    extra = {"mode_numbers": np.asarray(mode_n), "analysis_types": np.asarray(ats),
             "modal_a": np.asarray(ma, complex), "modal_b": np.asarray(mb, complex), "source": str(path)}
    return ModalModel(natural_frequencies=freqs, damping_ratios=zetas, shapes=shapes,
                      points=[dof_name(n, c) for n, c in nonzero], method=method, extra=extra)
