"""UFF dataset 58 (Function at Nodal DOF): FRF and coherence records read into an FRF table
(:func:`read_uff58_table`, used by :func:`vibroscope.io.frf_files.read_frf`) and an FRF written
as one record per output/input pair (:func:`write_frf_uff58`), through pyuff.

References
----------
.. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 58
   (Function at Nodal DOF),
   University of Cincinnati.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vibroscope.errors import LogFormatError
from vibroscope.io.frf_table import KIND_UNITS, FrfTable
from vibroscope.spectral.kinds import FRF_KIND_TABLE
from vibroscope.io.uff import (
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
from vibroscope.spectral import FRF

__all__ = ["write_frf_uff58"]

#: UFF specific data types (dataset 58 records 8-10): response quantity -> FRF kind
_SPEC_TO_KIND = {k.uff_data_type: k.name for k in FRF_KIND_TABLE.values()}
_FORCE_SPEC = (13, 9)  # excitation force, reaction force
_FUNC_TYPES = {
    0: "general", 1: "time response", 2: "auto spectrum", 3: "cross spectrum", 4: "FRF",
    5: "transmissibility", 6: "coherence", 7: "auto correlation", 8: "cross correlation", 9: "PSD",
    10: "ESD", 11: "probability density", 12: "spectrum", 18: "mode indicator function",
    26: "multiple coherence", 27: "order function",
}


def read_uff58_table(path: Path, input_name: str | None) -> FrfTable:
    u, types = open_uff(path)
    heads = {i: read_set(u, path, i, header_only=True) for i, t in enumerate(types) if t == 58}
    ftypes = {i: int(h.get("func_type", 0)) for i, h in heads.items()}
    frf_idx = [i for i, ft in ftypes.items() if ft == 4]
    if not frf_idx:
        found = ", ".join(f"function type {ft} ({_FUNC_TYPES.get(ft, '?')})"
                          for ft in sorted(set(ftypes.values()))) or "none"
        hint = ""
        if 1 in ftypes.values():
            hint = (f"; it holds time data: make it an MCAP log with `vibroscope convert {path} LOG.mcap`, "
                    "then run `vibroscope modal LOG.mcap --input ...` or `vibroscope analyse LOG.mcap`")
        elif 55 in types:
            hint = "; it holds UFF 55 mode shapes: read them with `vibroscope modal` on this file alone"
        raise LogFormatError(
            f"{path}: no UFF 58 FRF record (function type 4) among {len(types)} data sets "
            f"({dataset_summary(types)}); dataset-58 function types found: {found}{hint}")
    recs = {i: read_set(u, path, i) for i in frf_idx}

    def out_key(i: int, s: dict) -> str:
        node = int(s.get("rsp_node", 0) or 0)
        if node > 0:
            return dof_name(node, int(s.get("rsp_dir", 0) or 0))
        return read_label(s.get("id1")) or f"record{i + 1}"

    def in_key(s: dict) -> str:
        node = int(s.get("ref_node", 0) or 0)
        if node > 0:
            return dof_name(node, int(s.get("ref_dir", 0) or 0))
        return read_label(s.get("id4")) or (input_name or "input")

    i0 = frf_idx[0]
    f = np.asarray(recs[i0]["x"], float)
    outputs: list[str] = []
    inputs: list[str] = []
    pairs: dict[tuple[str, str], int] = {}
    for i in frf_idx:
        s = recs[i]
        x = np.asarray(s["x"], float)
        if x.shape != f.shape or not np.allclose(x, f, rtol=1e-6, atol=1e-9 * max(1.0, abs(f[-1]))):
            raise LogFormatError(f"{path}: data set #{i + 1}: FRF record has a frequency axis of {x.size} points "
                                 f"({x[0]:g}..{x[-1]:g} Hz) unlike data set #{i0 + 1} ({f.size} points, "
                                 f"{f[0]:g}..{f[-1]:g} Hz)")
        o, r = out_key(i, s), in_key(s)
        if (o, r) in pairs:
            o = f"{o} #{i + 1}"
        pairs[(o, r)] = i
        if o not in outputs:
            outputs.append(o)
        if r not in inputs:
            inputs.append(r)
    H = np.full((f.size, len(outputs), len(inputs)), np.nan, complex)
    for (o, r), i in pairs.items():
        H[:, outputs.index(o), inputs.index(r)] = np.asarray(recs[i]["data"])
    # coherence: multiple coherence (26) per output, or ordinary (6) for a single input
    coh = np.full((f.size, len(outputs)), np.nan)
    coh_from: dict[str, int] = {}
    for i, ft in ftypes.items():
        if ft not in (6, 26):
            continue
        s = read_set(u, path, i)
        o = out_key(i, s)
        if o not in outputs:
            continue
        if ft == 6 and (len(inputs) != 1 or in_key(s) != inputs[0]):
            continue
        if ft == 6 and o in coh_from and ftypes[coh_from[o]] == 26:
            continue  # the multiple coherence wins
        x = np.asarray(s["x"], float)
        if x.shape != f.shape or not np.allclose(x, f, rtol=1e-6, atol=1e-9 * max(1.0, abs(f[-1]))):
            raise LogFormatError(f"{path}: data set #{i + 1}: coherence record for {o!r} has a frequency axis "
                                 f"unlike its FRF (data set #{i0 + 1})")
        coh[:, outputs.index(o)] = np.real(np.asarray(s["data"]))
        coh_from[o] = i
    # kind and units from the specific data types
    kinds = set()
    for i in frf_idx:
        s = recs[i]
        num, den = int(s.get("ordinate_spec_data_type", 0) or 0), int(s.get("orddenom_spec_data_type", 0) or 0)
        kinds.add(_SPEC_TO_KIND.get(num) if den in _FORCE_SPEC else None)
    kind = kinds.pop() if len(kinds) == 1 else None
    if kind:
        units = KIND_UNITS[kind]
    else:
        labs = {(read_label(recs[i].get("ordinate_axis_units_lab")), read_label(recs[i].get("orddenom_axis_units_lab")))
                for i in frf_idx}
        num, den = labs.pop() if len(labs) == 1 else ("", "")
        units = f"{num}/{den}" if num and den else num
    binary = sorted({int(recs[i].get("binary", 0) or 0) for i in frf_idx})
    extra = {"records": [i + 1 for i in frf_idx], "coherence_records": {o: i + 1 for o, i in coh_from.items()},
             "binary": binary, "id2": read_label(recs[i0].get("id2"))}
    return FrfTable(path=path, frequencies=f, H=H, coh=coh, inputs=inputs, outputs=outputs, named=True,
                    kind=kind, units=units, fmt="uff58", extra=extra)


def write_frf_uff58(frf: FRF, path: str | Path, *, binary: bool = False) -> Path:
    """Write an FRF as a Universal File: one dataset-58 record per output/input pair.

    Parameters
    ----------
    frf : FRF
        ``H`` complex (n_freqs, n_outputs, n_inputs) on ``frequencies`` (Hz, at least 2).
    path : str or Path
        The file to write (overwritten).
    binary : bool, optional
        Write binary 58 records (``58b``: double-precision data) instead of ASCII.

    Returns
    -------
    Path
        `path`.

    Raises
    ------
    ValueError
        If the FRF has fewer than 2 frequencies.

    See Also
    --------
    vibroscope.io.read_frf : Read the FRF back (the conventions written here).

    Notes
    -----
    Each FRF record has function type 4; its response DOF comes from the output's name when it
    reads as a node DOF (``"12+Z"``, ``"3-X"``, ``"5"``), else response node 0 and the name in
    ID line 1; its reference DOF likewise from the input's name, else reference node 0 and
    the name in ID line 4 -- the conventions :func:`read_frf` reads back. The specific data
    types state the kind (numerator 12/11/8 over 13, excitation force; 0/0 when the kind is
    None); the abscissa is frequency (18) in Hz, evenly spaced when the steps agree to 1e-6.

    For a single input, each output's coherence is written as a function-type-6 record when
    any of it is finite; pyuff writes non-finite values (NaN, inf) as 0, in coherence and FRF
    alike, since the format has no NaN. With several inputs the coherence is the multiple
    coherence (function type 26), which pyuff cannot write, so none is written. Output/input
    pairs whose ``H`` is NaN throughout are not written.

    Precision: ASCII data values are written with 12 significant digits (``E20.12``); the
    abscissa minimum and increment (or, unevenly spaced in ASCII, each abscissa value) with
    6 (``E13.5``), the format's own single-precision abscissa. ID lines hold 80 characters.

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 58
       (Function at Nodal DOF), University of Cincinnati.
    """
    import pyuff

    path = Path(path)
    f = np.asarray(frf.frequencies, float)
    if f.size < 2:
        raise ValueError(f"{f.size=}: a UFF 58 record needs at least 2 frequencies")
    d = np.diff(f)
    even = bool(np.allclose(d, d[0], rtol=1e-6, atol=0.0))
    kind = frf.kind
    k = FRF_KIND_TABLE.get(kind)
    num_spec, den_spec = (k.uff_data_type, 13) if k else (0, 0)
    num_lab, den_lab = (k.response_unit, "N") if k else ("NONE", "NONE")
    common = dict(binary=int(bool(binary)), abscissa_spacing=int(even), abscissa_spec_data_type=18,
                  abscissa_axis_units_lab="Hz", x=f, id3=date_line())
    dsets: list[dict] = []
    one_input = frf.H.shape[2] == 1
    for i, inp in enumerate(frf.inputs):
        rdof = parse_dof(inp)
        ref_node, ref_dir = rdof if rdof else (0, 0)
        for o, out in enumerate(frf.outputs):
            h = np.asarray(frf.H[:, o, i], complex)
            if np.all(np.isnan(h)):
                continue
            odof = parse_dof(out)
            rsp_node, rsp_dir = odof if odof else (0, 0)
            ids = dict(id1=id_line(out), id2=id_line(f"{frf.estimator} FRF"), id4=id_line(inp))
            ds = pyuff.prepare_58(func_type=4, rsp_node=int(rsp_node), rsp_dir=int(rsp_dir),
                                  ref_node=int(ref_node), ref_dir=int(ref_dir), data=h.copy(),
                                  ordinate_spec_data_type=num_spec, orddenom_spec_data_type=den_spec,
                                  ordinate_axis_units_lab=num_lab, orddenom_axis_units_lab=den_lab,
                                  **ids, **common)
            ds["func_id"] = len(dsets) + 1
            dsets.append(ds)
            c = np.asarray(frf.coherence[:, o], float) if frf.coherence.size else np.full(f.size, np.nan)
            if one_input and np.any(np.isfinite(c)):
                ids = dict(ids, id2=id_line(f"{frf.estimator} coherence"))
                ds = pyuff.prepare_58(func_type=6, rsp_node=int(rsp_node), rsp_dir=int(rsp_dir),
                                      ref_node=int(ref_node), ref_dir=int(ref_dir), data=c.copy(),
                                      ordinate_spec_data_type=0, orddenom_spec_data_type=0,
                                      **ids, **common)
                ds["func_id"] = len(dsets) + 1
                dsets.append(ds)
    if not dsets:
        raise ValueError("the FRF is NaN throughout: nothing to write")
    remove_existing(path)  # pyuff's binary writer is only reliable in 'add' mode
    u = pyuff.UFF(str(path))
    u.write_sets(dsets, mode="add")
    return path
