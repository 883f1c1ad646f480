"""Mode shapes in a rerun recording: the sensors displaced along their measuring directions over
the ``animation`` timeline, the deformed structure as a line strip, and a table of the modes.

rerun is imported inside the functions: importing this module never imports it.
"""

from __future__ import annotations

import numpy as np

from vibroscope.viewers._common import mode_label, sensor_geometry
from vibroscope.viewers.rerun_paths import mode_entity

__all__ = ["mode_frames", "node_frames", "log_modes", "FRAMES"]


#: animation frames per cycle of a mode
FRAMES = 40


def mode_frames(shape: np.ndarray, positions: np.ndarray, directions: np.ndarray, scale: float,
                frames: int = FRAMES) -> np.ndarray:
    """Displaced point positions over one cycle of a mode.

    ``x_k = positions + scale · Re(φ̂ · exp(j 2π k / frames)) · directions`` for
    ``k = 0 … frames − 1``, with ``φ̂ = φ / max|φ|``.

    Parameters
    ----------
    shape : array_like, complex, shape (n_points,)
    positions, directions : ndarray, shape (n_points, 3)
    scale : float
        Largest displacement in m.
    frames : int, optional

    Returns
    -------
    ndarray, shape (frames, n_points, 3)
    """
    phi = np.asarray(shape, dtype=complex)
    m = np.max(np.abs(phi)) if phi.size else 0.0
    phi = phi / m if m > 0 else phi
    ph = np.exp(2j * np.pi * np.arange(frames) / frames)
    amp = np.real(phi[None, :] * ph[:, None])  # (frames, n_points)
    return positions[None, :, :] + scale * amp[:, :, None] * directions[None, :, :]


def _mode_table(modal) -> str:
    fn = np.asarray(modal.natural_frequencies, dtype=float)
    z = np.asarray(modal.damping_ratios, dtype=float)
    extra = getattr(modal, "extra", {}) or {}
    mpc = extra.get("mpc")
    lines = [f"# Modes ({getattr(modal, 'method', '')})", "",
             f"{len(modal.points)} points: " + ", ".join(f"`{p}`" for p in modal.points), "",
             "| # | f [Hz] | ζ [%] |" + (" MPC |" if mpc is not None else ""),
             "|---|---|---|" + ("---|" if mpc is not None else "")]
    for r in range(fn.size):
        zs = f"{100 * z[r]:.3f}" if np.isfinite(z[r]) else "n/a"
        row = f"| {r + 1} | {fn[r]:.4f} | {zs} |"
        if mpc is not None:
            row += f" {float(np.asarray(mpc)[r]):.3f} |"
        lines.append(row)
    return "\n".join(lines)


def _structure_scale(positions: np.ndarray) -> float:
    ext = float(np.max(np.ptp(positions, axis=0))) if len(positions) > 1 else 0.0
    return 0.15 * ext if ext > 0 else 0.2


def log_modes(rec, modal, coords, frames: int) -> None:
    """Log the mode shapes: each mode animated over the ``animation`` timeline, and the mode table.

    ``/modes/mode_<r>_<f>Hz`` (:func:`vibroscope.viewers.rerun_paths.mode_entity`) holds the
    sensors displaced along their measuring directions (:func:`mode_frames`; the largest
    displacement is 15 % of the structure's size) and a line strip joining the deformed locations
    (:func:`node_frames`); ``.../undeformed`` the sensors and structure at rest (static, grey);
    ``/modes/table`` a markdown table of the modes.

    Parameters
    ----------
    rec : rerun.RecordingStream
        The recording.
    modal : ModalModel
        ``natural_frequencies`` (Hz), ``damping_ratios``, ``shapes`` (complex,
        (n_modes, n_points)), ``points``, ``method``.
    coords : mapping or None
        Sensor positions and directions (:func:`vibroscope.viewers._common.sensor_geometry`);
        points on a line when None.
    frames : int
        Animation frames per cycle.
    """
    import rerun as rr

    fn = np.atleast_1d(np.asarray(modal.natural_frequencies, dtype=float))
    zeta = np.atleast_1d(np.asarray(modal.damping_ratios, dtype=float))
    shapes = np.atleast_2d(np.asarray(modal.shapes, dtype=complex))
    points = list(modal.points)
    pos, dirs, _ = sensor_geometry(points, coords)
    scale = _structure_scale(pos)
    ext = scale / 0.15  # the structure's size (m), for radii
    node_pos, members = _nodes(pos)
    labels = [p.split(".")[0].split("/")[-1] or p for p in points]  # the topic's last name: "m1", "s01"
    rec.log("modes/table", rr.TextDocument(_mode_table(modal), media_type=rr.MediaType.MARKDOWN), static=True)
    n = len(points)
    frame_idx = np.arange(frames)
    grey = [150, 150, 150]
    for r in range(fn.size):
        ent = mode_entity(r, fn[r])
        rec.log(ent + "/undeformed", rr.Points3D(pos, radii=0.01 * ext, colors=grey,
                                                 labels=labels if n <= 8 else None),
                rr.LineStrips3D([node_pos], colors=grey, radii=0.004 * ext), static=True)
        rec.log(ent, rr.TextDocument(f"Mode {r + 1}: {mode_label(fn[r], zeta[r])}; "
                                     f"largest displacement drawn {scale:.3g} m"), static=True)
        X = mode_frames(shapes[r], pos, dirs, scale, frames)  # (frames, n, 3)
        strips = node_frames(X, pos, node_pos, members)  # (frames, n_nodes, 3)
        colour = np.array([220, 80, 40], dtype=np.uint8)
        rec.send_columns(
            ent,
            indexes=[rr.TimeColumn("animation", sequence=frame_idx)],
            columns=[
                *rr.Points3D.columns(positions=X.reshape(-1, 3), colors=np.tile(colour, (frames * n, 1)),
                                     radii=np.full(frames * n, 0.015 * ext, dtype=np.float32)
                                     ).partition(lengths=np.full(frames, n)),
                *rr.LineStrips3D.columns(strips=list(strips)),
            ],
        )


def _nodes(pos: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """Distinct sensor locations along the structure's longest extent, and the sensors at each."""
    if len(pos) == 0:
        return pos.reshape(0, 3), []
    axis = int(np.argmax(np.ptp(pos, axis=0)))
    keys = [tuple(np.round(p, 6)) for p in pos]
    uniq = list(dict.fromkeys(keys))
    node_pos = np.array(uniq, dtype=float)
    members = [np.array([k for k, kk in enumerate(keys) if kk == u]) for u in uniq]
    order = np.argsort(node_pos[:, axis], kind="stable")
    return node_pos[order], [members[i] for i in order]


def node_frames(X: np.ndarray, positions: np.ndarray, node_pos: np.ndarray, members: list) -> np.ndarray:
    """Deformed locations: each node moved by the sum of its sensors' displacements.

    Sensors at one location measuring along different axes (a tower's two horizontal axes)
    together give that location's displacement vector; the line strip of the deformed
    structure joins these.

    Parameters
    ----------
    X : ndarray, shape (frames, n_points, 3)
        Displaced sensor positions (:func:`mode_frames`).
    positions : ndarray, shape (n_points, 3)
        Undeformed sensor positions.
    node_pos : ndarray, shape (n_nodes, 3)
        Distinct locations, in strip order.
    members : list of ndarray
        Indices of the sensors at each location.

    Returns
    -------
    ndarray, shape (frames, n_nodes, 3)
    """
    D = X - positions[None]
    return np.stack([node_pos[j][None, :] + D[:, m, :].sum(axis=1) for j, m in enumerate(members)], axis=1)
