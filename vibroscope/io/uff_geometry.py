"""Node geometry in Universal Files: node coordinates written as datasets 164 (SI units) and 15
(:func:`write_geometry_uff15`) and read from datasets 15 and 2411, scaled by a dataset-164 length
factor (:func:`read_geometry`), through pyuff.

References
----------
.. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", datasets 15
   (Nodes), 164 (Units) and 2411 (Nodes - Double Precision),
   University of Cincinnati.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from vibroscope.errors import LogFormatError
from vibroscope.io.uff import dataset_summary, open_uff, read_set, remove_existing

__all__ = ["write_geometry_uff15", "read_geometry"]

def write_geometry_uff15(path: str | Path, node_ids: Sequence[int], xyz: np.ndarray) -> Path:
    """Write node coordinates as UFF dataset 164 (SI units) and 15 (nodes).

    Parameters
    ----------
    path : str or Path
        The file to write (overwritten).
    node_ids : sequence of int, shape (n_nodes,)
        Node labels, unique, positive.
    xyz : array_like, shape (n_nodes, 3)
        Coordinates in m.

    Returns
    -------
    Path
        `path`.

    Raises
    ------
    ValueError
        If the shapes disagree, `xyz` is not finite, or node ids repeat or are not positive.

    See Also
    --------
    read_geometry : Read the coordinates back.

    Notes
    -----
    Dataset 15 stores coordinates with 6 significant digits (``E13.5``); a units record
    (dataset 164, SI, length factor 1) precedes it so that :func:`read_geometry` and other
    readers know the coordinates are in metres.

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", datasets 15
       (Nodes) and 164 (Units), University of Cincinnati.
    """
    import pyuff

    path = Path(path)
    ids = np.asarray(node_ids)
    pts = np.asarray(xyz, float)
    if ids.ndim != 1 or pts.shape != (ids.size, 3):
        raise ValueError(f"{ids.shape=} node_ids need xyz of shape ({ids.size}, 3), got {pts.shape=}")
    if ids.size == 0 or not np.all(np.isfinite(pts)):
        raise ValueError("xyz must hold at least one node and only finite coordinates (m)")
    if not np.issubdtype(ids.dtype, np.integer) and not np.all(ids == np.round(ids)):
        raise ValueError(f"node_ids must be integers, got {ids[:5]}")
    ids = ids.astype(int)
    if np.any(ids <= 0) or np.unique(ids).size != ids.size:
        raise ValueError("node_ids must be positive and unique")
    units = pyuff.prepare_164(units_code=1, units_description="SI: Meter (newton)", temp_mode=2,
                              length=1.0, force=1.0, temp=1.0, temp_offset=273.15)
    nodes = pyuff.prepare_15(node_nums=ids, def_cs=np.zeros(ids.size, int), disp_cs=np.zeros(ids.size, int),
                             color=np.ones(ids.size, int), x=pts[:, 0].copy(), y=pts[:, 1].copy(),
                             z=pts[:, 2].copy())
    remove_existing(path)
    pyuff.UFF(str(path)).write_sets([units, nodes], mode="add")
    return path


def read_geometry(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read node coordinates from UFF dataset 15 or 2411 records.

    Parameters
    ----------
    path : str or Path
        A Universal File. Every dataset-15 (Nodes) and dataset-2411 (Nodes - Double Precision)
        record contributes its nodes in file order. When a dataset-164 (Units) record is
        present, coordinates are divided by its length factor (the UFF convention for
        converting file units to SI); otherwise they are taken as metres.

    Returns
    -------
    node_ids : ndarray of int, shape (n_nodes,)
    xyz : ndarray, shape (n_nodes, 3)
        Coordinates in m, in each node's definition coordinate system (coordinate systems,
        dataset 2420, are not applied).

    Raises
    ------
    LogFormatError
        If the file is unreadable, holds no node record (names the datasets found), or a node
        id occurs twice.

    See Also
    --------
    write_geometry_uff15 : Write node coordinates as UFF dataset 15.

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", datasets 15,
       164 and 2411, University of Cincinnati.
    """
    path = Path(path)
    u, types = open_uff(path)
    factor = 1.0
    ids_l, xyz_l = [], []
    for i, t in enumerate(types):
        if t == 164:
            s = read_set(u, path, i)
            lf = float(s.get("length", 1.0))
            if not (np.isfinite(lf) and lf > 0):
                raise LogFormatError(f"{path}: data set #{i + 1} (units, 164): length factor {lf!r} is not positive")
            factor = lf
        elif t in (15, 2411):
            s = read_set(u, path, i)
            n = np.asarray(s["node_nums"], float)
            ids_l.append(np.round(n).astype(int))
            xyz_l.append(np.column_stack([np.asarray(s[k], float) for k in ("x", "y", "z")]))
    if not ids_l:
        raise LogFormatError(f"{path}: no node record (dataset 15 or 2411) among {len(types)} data sets "
                             f"({dataset_summary(types)})")
    ids = np.concatenate(ids_l)
    xyz = np.vstack(xyz_l) / factor
    uniq, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):
        raise LogFormatError(f"{path}: node ids {uniq[counts > 1][:10].tolist()} occur more than once")
    return ids, xyz
