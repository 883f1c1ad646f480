"""Mode sets made elsewhere: UFF 55 mode shapes (with the UFF 15 / 2411 geometry in the same
file), model files (``kind = "modal"`` written by ``vibroscope modal --export-model``, or a
``kind = "lumped"`` model's own modes) and the ``MODES.json`` of ``vibroscope modal``, read as
one :class:`~vibroscope.modal.ModalModel` with the sensor geometry where the file holds one.

References
----------
.. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", datasets 15, 55
   and 2411, University of Cincinnati.
.. [2] D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research Studies
   Press, 2000, §2.7 (modal constants ``A_r,jk = φ_jr φ_kr``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vibroscope.errors import LogFormatError, VibroscopeError
from vibroscope.io.coords import SensorCoords
from vibroscope.modal import ModalModel, normalize_shapes

__all__ = ["ModeSet", "read_mode_set", "is_mode_set", "MODE_SET_SUFFIXES"]

#: suffixes read as mode sets by :func:`read_mode_set` (a ``.json`` only when it is a MODES.json)
MODE_SET_SUFFIXES = (".uff", ".unv", ".uf", ".toml", ".json")


@dataclass(frozen=True, eq=False)
class ModeSet:
    """Modes read from a file, with where their points are.

    Attributes
    ----------
    modes : ModalModel
        Natural frequencies (Hz), damping ratios (NaN where the file has none), complex shapes
        ``(n_modes, n_points)`` at `modes.points`.
    coords : SensorCoords or None
        Positions (m) and measuring directions of the points when the file holds a geometry
        (UFF 15 / 2411 nodes beside the UFF 55 records); None otherwise.
    source : str
        The file read.
    format : str
        ``"uff55"``, ``"model file (modal)"``, ``"model file (lumped)"`` or ``"MODES.json"``.
    """

    modes: ModalModel
    coords: SensorCoords | None
    source: str
    format: str

    def __repr__(self) -> str:
        return (f"ModeSet({len(self.modes)} modes at {len(self.modes.points)} points from {self.source!r}, "
                f"{self.format}{', with geometry' if self.coords is not None else ''})")


def is_mode_set(path: str | Path) -> bool:
    """Whether `path` holds modes rather than FRFs or time data (cheap: no shapes are read).

    Parameters
    ----------
    path : str or Path
        A file.

    Returns
    -------
    bool
        True for a UFF with dataset-55 records and no dataset-58 record, a ``.toml`` model file,
        or a ``.json`` whose top level holds ``"modes"`` (a MODES.json).
    """
    p = Path(path)
    suf = p.suffix.lower()
    if not p.is_file():
        return False
    if suf == ".toml":
        return True
    if suf == ".json":
        try:
            doc = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError):
            return False
        return isinstance(doc, dict) and isinstance(doc.get("modes"), list)
    if suf in (".uff", ".unv", ".uf"):
        from vibroscope.io.frf_files import uff_datasets

        try:
            types = uff_datasets(p)
        except LogFormatError:
            return False
        return 55 in types and 58 not in types
    return False


def read_mode_set(path: str | Path, *, coords: str | Path | None = None) -> ModeSet:
    """Read a set of modes from a UFF 55 file, a model file or a MODES.json.

    Parameters
    ----------
    path : str or Path
        * ``.uff``/``.unv``/``.uf``: dataset-55 records (:func:`~vibroscope.io.frf_files.read_modes_uff55`;
          points ``"{node}+X|Y|Z"``); dataset-15/2411 nodes in the same file give the geometry.
        * ``.toml``: a model file (:func:`~vibroscope.models.modelfile.load_model`).
          ``kind = "modal"``: one mode per pole, the shape at the outputs (points = output
          channels) from the modal constants ``A_r,oi = φ_o φ_i`` of the input whose column is
          largest (proportional to ``φ_o``, what the MAC needs). ``kind = "lumped"``: the
          oscillatory modes of its linear part (:meth:`~vibroscope.models.LumpedModel.modes`),
          points = the DOFs (or the model's named points), each named by the channel of the
          first ``[[output]]`` on it (so they meet a test's channels by name), else by its own
          name. Shapes are scaled to unit maximum modulus.
        * ``.json``: the ``MODES.json`` of ``vibroscope modal --json``.
    coords : str or Path, optional
        Sensor coordinates (CSV or UFF geometry, :func:`~vibroscope.io.coords.read_coords`)
        replacing the file's own geometry.

    Returns
    -------
    ModeSet

    Raises
    ------
    LogFormatError
        If the file is missing, unreadable, holds no mode (names the datasets found), or a
        MODES.json entry lacks a field (names the mode).
    ModelFileError
        If a model file is invalid, or is a transfer function (no mode shapes).
    """
    p = Path(path)
    if not p.is_file():
        raise LogFormatError(f"{p}: no such file")
    suf = p.suffix.lower()
    geometry = None
    if suf == ".toml":
        modes, fmt = _model_file_modes(p)
    elif suf == ".json":
        modes, fmt = _modes_json(p), "MODES.json"
    else:
        from vibroscope.io.frf_files import read_modes_uff55, uff_datasets

        modes, fmt = read_modes_uff55(p), "uff55"
        if coords is None and any(t in (15, 2411) for t in uff_datasets(p)):
            from vibroscope.io.coords import read_coords

            try:
                geometry = read_coords(p, modes.points)
            except VibroscopeError:
                geometry = None  # nodes of the shapes absent from the geometry: laid out on a line
    if coords is not None:
        from vibroscope.io.coords import read_coords

        geometry = read_coords(coords, modes.points)
    return ModeSet(modes, geometry, str(p), fmt)


def _model_file_modes(p: Path) -> tuple[ModalModel, str]:
    from vibroscope.errors import ModelFileError
    from vibroscope.models.lumped import LumpedModel
    from vibroscope.models.modal_coordinates import modal_constants
    from vibroscope.models.modal_model import PoleResidueModel
    from vibroscope.models.modelfile import load_model

    model = load_model(p)
    name = getattr(model, "name", "") or p.stem
    if isinstance(model, PoleResidueModel):
        A = modal_constants(model)  # (n_modes, n_outputs, n_inputs), φ_o φ_i per mode
        cols = np.linalg.norm(A, axis=1)  # (n_modes, n_inputs)
        best = np.argmax(cols, axis=1)
        shapes = np.array([A[r, :, best[r]] for r in range(A.shape[0])])
        points = [o.channel or o.dof for o in model.outputs]
        return ModalModel(natural_frequencies=model.natural_frequencies, damping_ratios=model.damping_ratios,
                          shapes=normalize_shapes(shapes), points=points, method=f"model file {name}",
                          extra={"source": str(p)}), "model file (modal)"
    if isinstance(model, LumpedModel):
        md = model.modes()
        pts = list(model.point_names())
        if pts:
            P = np.array([model.point_vector(q) for q in pts])  # (n_points, n_dofs)
            shapes = np.asarray(md.shapes) @ P.T
        else:
            pts, shapes = list(md.dofs), np.asarray(md.shapes)
        if not len(md):
            raise ModelFileError(f"{p}: the lumped model {name!r} has no oscillatory mode")
        logged = {}
        for o in model.outputs:  # a DOF that an output logs is named by that output's channel
            if o.channel and o.dof not in logged:
                logged[o.dof] = o.channel
        pts = [logged.get(q, q) for q in pts]
        return ModalModel(natural_frequencies=md.natural_frequencies, damping_ratios=md.damping_ratios,
                          shapes=normalize_shapes(shapes), points=pts, method=f"model file {name}",
                          extra={"source": str(p)}), "model file (lumped)"
    raise ModelFileError(f"{p}: a {type(model).__name__} has no mode shapes; a mode set needs kind = \"modal\" "
                         f"(vibroscope modal --export-model) or kind = \"lumped\"")


def _modes_json(p: Path) -> ModalModel:
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise LogFormatError(f"{p}: not a MODES.json ({exc})") from None
    if not (isinstance(doc, dict) and isinstance(doc.get("modes"), list)):
        raise LogFormatError(f"{p}: not a MODES.json (no top-level \"modes\" list)")
    points = [str(x) for x in doc.get("points") or []]
    f, z, S = [], [], []
    for r, m in enumerate(doc["modes"], start=1):
        try:
            f.append(float(m["frequency_hz"]))
            zr = m.get("damping_ratio")
            z.append(np.nan if zr is None else float(zr))
            sh = m["shape"]
            if not points:
                points = list(sh)
            S.append([complex(*sh[q]) for q in points])
        except (KeyError, TypeError, ValueError) as exc:
            raise LogFormatError(f"{p}: mode {r}: missing or bad field ({type(exc).__name__}: {exc})") from None
    if not f:
        raise LogFormatError(f"{p}: the MODES.json holds no mode")
    return ModalModel(natural_frequencies=f, damping_ratios=z, shapes=np.array(S, complex).reshape(len(f), len(points)),
                      points=points, method=str(doc.get("method") or "MODES.json"),
                      extra={"source": str(p), "normalisation": doc.get("normalisation", "unit_maximum")})
