"""Opening a finished recording in the rerun viewer program that rerun-sdk ships, detached, with
one line saying why when none can open.
"""

from __future__ import annotations

import warnings
from pathlib import Path

__all__ = ["open_in_viewer", "show_recording", "viewer_executable", "VIEWER_PORT"]


#: the port a spawned rerun viewer listens on (rerun's default)
VIEWER_PORT = 9876


def show_recording(path: str | Path) -> bool:
    """:func:`open_in_viewer`, with a one-line warning ``--spawn: no rerun viewer opened: WHY`` when none opens.

    Parameters
    ----------
    path : str or Path
        The complete recording.

    Returns
    -------
    bool
        Whether a viewer took it.
    """
    why = open_in_viewer(path)
    if why is not None:
        warnings.warn(f"--spawn: no rerun viewer opened: {why}", stacklevel=2)
    return why is None


def viewer_executable() -> str | None:
    """The rerun viewer program: the ``rerun`` that the rerun-sdk package installed beside this
    Python (``bin/`` of its virtual environment), else ``rerun`` on ``PATH``, else the binary inside
    the ``rerun_cli`` package; None when there is none.

    Returns
    -------
    str or None
    """
    import importlib.util
    import os
    import shutil
    import sys

    exe = "rerun.exe" if sys.platform.startswith("win") else "rerun"
    beside = Path(sys.executable).parent / exe
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    found = shutil.which("rerun")
    if found:
        return found
    try:
        spec = importlib.util.find_spec("rerun_cli")
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.origin:
        inner = Path(spec.origin).parent / exe
        if inner.is_file() and os.access(inner, os.X_OK):
            return str(inner)
    return None


def _listening(port: int, timeout: float = 0.2) -> bool:
    import socket

    try:
        with socket.create_connection(("127.0.0.1", port), timeout=timeout):
            return True
    except OSError:
        return False


def open_in_viewer(path: str | Path, *, port: int | None = None, settle_s: float = 1.5,
                   executable: str | None = None) -> str | None:
    """Open a finished ``.rrd`` file in the rerun viewer that rerun-sdk ships; None, or one line saying why not.

    The viewer program (:func:`viewer_executable`) is started detached (its own session: Ctrl-C
    on the command does not close it) as ``rerun PATH``; rerun itself hands the file to a viewer
    already listening on its port, else opens a window. This process never streams to the viewer,
    so nothing here can wait on it (:func:`rerun.spawn` looks on ``PATH`` only, is ignored without
    a global recording, and a gRPC flush to a viewer that never answers waits for ever, deaf to
    Ctrl-C). The viewer is judged after `settle_s`: still running, or ended with status 0 (handed
    over), is success; a viewer that cannot open its window ends at once with an error, whose
    last line is the reason. On Linux with no ``DISPLAY``/``WAYLAND_DISPLAY``/``WAYLAND_SOCKET``
    and no viewer listening, nothing is started.

    Parameters
    ----------
    path : str or Path
        The recording (complete: written and closed).
    port : int, optional
        The port a running viewer listens on; default :data:`VIEWER_PORT` (9876, rerun's), read
        at call time.
    settle_s : float, optional
        How long (s) to watch the started viewer; default 1.5.
    executable : str, optional
        The viewer program; default :func:`viewer_executable`.

    Returns
    -------
    str or None
        None when the viewer took the file, else the reason, one line.
    """
    import os
    import subprocess
    import sys
    import tempfile
    import time

    port = VIEWER_PORT if port is None else int(port)
    running = _listening(port)
    if not running and sys.platform.startswith("linux") and not any(
            os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")):
        return "no display (DISPLAY and WAYLAND_DISPLAY are not set), so no viewer window can open"
    exe = executable or viewer_executable()
    if exe is None:
        return "no rerun viewer program found (pip install rerun-sdk installs one beside Python)"
    log = tempfile.TemporaryFile()  # unlinked at once: the viewer's start-up errors, no file left behind
    try:
        proc = subprocess.Popen([exe, "--port", str(port), str(path)], stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=log, start_new_session=True,
                                env={**os.environ, "RERUN_APP_ONLY": "true"})
    except OSError as exc:
        log.close()
        return f"cannot start {exe}: {exc.strerror or exc}"
    try:
        end = time.monotonic() + settle_s
        while proc.poll() is None and time.monotonic() < end:
            time.sleep(0.05)
        if proc.returncode is None or proc.returncode == 0:
            return None
        log.seek(0)
        text = [_strip_ansi(ln) for ln in log.read().decode("utf-8", "replace").splitlines() if ln.strip()]
        errs = [ln for ln in text if "error" in ln.lower()] or text
        return f"{exe} ended at start (status {proc.returncode})" + (
            f": {' '.join(errs[-1].split())[:300]}" if errs else "")
    finally:
        log.close()


def _strip_ansi(text: str) -> str:
    import re

    return re.sub(r"\x1b\[[0-9;]*m", "", text)
