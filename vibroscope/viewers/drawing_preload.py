"""Imported once by the drawing server (:mod:`vibroscope.viewers.drawing_server`) before it forks the
workers: matplotlib (Agg), PIL, the figure and acquisition plots, the integrals of the
kinematics figure, rerun (as :func:`vibroscope.viewers.rerun_recording.preload` does, without
pandas) with the recording code, and one small figure drawn
(:func:`~vibroscope.viewers.drawing_server.warm_up`); the server then ends without tearing the
interpreter down. Importing it has these effects and nothing else; no other module imports it.
Imported anywhere else (``tests/test_docstrings.py`` imports every module of the package) it only
loads and draws: the fast ending is registered only inside the server (:func:`_in_forkserver`),
since ``os._exit(0)`` at exit would replace that process's exit status (a failing pytest run
exited 0)."""

import atexit
import contextlib
import os
import sys

from vibroscope.viewers import acquisition, figures  # noqa: F401
from vibroscope.spectral import integration  # noqa: F401
from vibroscope.viewers.drawing_server import warm_up

figures.preload()
with contextlib.suppress(ImportError):  # rerun-sdk is an extra: without it the recording says so itself
    from vibroscope.viewers import rerun_recording, rerun_view  # noqa: F401

    rerun_recording.preload(pandas=False)
try:
    warm_up()
except Exception:  # pragma: no cover - a worker then loads the fonts itself
    pass


def _in_forkserver() -> bool:
    """Whether this import runs inside :func:`multiprocessing.forkserver.main` (the server's
    preload), read from the calling frames."""
    frame = sys._getframe(1)
    while frame is not None:
        code = frame.f_code
        if code.co_name == "main" and code.co_filename.endswith(os.path.join("multiprocessing", "forkserver.py")):
            return True
        frame = frame.f_back
    return False


# the server holds nothing to flush or clean up: when its lifeline closes it ends at once, not after
# the ~0.25 s it takes to tear down matplotlib and rerun (registered last, so run first; forked
# workers end with os._exit and never run atexit handlers). Only there: anywhere else os._exit(0)
# would replace the process's own exit status.
if _in_forkserver():
    atexit.register(os._exit, 0)
