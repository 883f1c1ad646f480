"""Reading a rerun recording back with rerun's own reader, as ``{entity: {column: values}}``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["read_rrd"]


def read_rrd(path: str | Path, *, blueprint: bool = False) -> dict[str, dict[str, Any]]:
    """Read a recording back with rerun's own reader (:class:`rerun.chunk.RrdReader`).

    Parameters
    ----------
    path : str or Path
        An ``.rrd`` file.
    blueprint : bool, optional
        Read the (first) blueprint store of the file instead of the recording.

    Returns
    -------
    dict
        ``{entity_path: {column: values}}``, entity paths as rerun writes them
        (``"/signals/acc/s1.z"``). Columns are named as rerun names them: timelines by their
        name (int64 values: ns for durations, the index for sequences) and components as
        ``"Archetype:field"`` (``"Scalars:scalars"``, ``"Points3D:positions"``). Rows of the
        temporal chunks of an entity are concatenated in file order; a component with one
        value per row becomes a 1-D (or (n, k)) array, otherwise a list with one array per row.
        Static data are under the key ``"static"`` as ``{component: value of its last row}``.

    Raises
    ------
    ValueError
        If the file holds no such store.
    """
    from rerun.chunk import RrdReader

    reader = RrdReader(str(path))
    store = None
    if blueprint:
        bps = reader.blueprints()
        if not bps:
            raise ValueError(f"{path}: no blueprint store")
        store = bps[0]
    parts: dict[str, dict[str, list]] = {}
    out: dict[str, dict[str, Any]] = {}
    for chunk in reader.stream(store=store):
        ent = chunk.entity_path
        rb = chunk.to_record_batch()
        d = out.setdefault(ent, {})
        for name, col in zip(rb.schema.names, rb.columns):
            if name == "rerun.controls.RowId":
                continue
            vals = _rows(col)
            if chunk.is_static:
                d.setdefault("static", {})[name] = vals[-1] if len(vals) else None
            else:
                parts.setdefault(ent, {}).setdefault(name, []).extend(vals)
    for ent, cols in parts.items():
        for name, rows in cols.items():
            out[ent][name] = _stack(rows)
    return out


def _rows(col) -> list:
    """One value per row of an arrow column: numpy arrays for lists (fixed-size lists reshaped to
    (n, k)), int64 for durations and timestamps (ns), str for strings."""
    import pyarrow as pa

    if pa.types.is_duration(col.type) or pa.types.is_timestamp(col.type):
        return list(np.asarray(col.cast(pa.int64()).to_numpy(zero_copy_only=False)))
    return list(_flat(col))


def _flat(arr):
    import pyarrow as pa

    t = arr.type
    if pa.types.is_fixed_size_list(t):
        return np.asarray(_flat(arr.flatten())).reshape(len(arr), t.list_size)
    if pa.types.is_list(t) or pa.types.is_large_list(t):
        offsets = np.asarray(arr.offsets.to_numpy(zero_copy_only=False), dtype=np.int64)
        inner = _flat(arr.values)
        valid = arr.is_valid().to_numpy(zero_copy_only=False)
        return [inner[offsets[k]:offsets[k + 1]] if valid[k] else None for k in range(len(arr))]
    if pa.types.is_primitive(t):
        return arr.to_numpy(zero_copy_only=False)
    return arr.to_pylist()


def _stack(rows: list):
    if rows and all(r is not None and not isinstance(r, str) and np.ndim(r) >= 1 and len(r) == 1 for r in rows):
        if all(isinstance(r, np.ndarray) for r in rows):
            return np.concatenate(rows)
        return [r[0] for r in rows]
    if rows and all(np.ndim(r) == 0 for r in rows):
        return np.asarray(rows)
    return rows
