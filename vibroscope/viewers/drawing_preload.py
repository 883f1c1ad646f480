"""Imported once by the drawing server (:mod:`vibroscope.viewers.drawing_server`) before it forks the
workers: matplotlib (Agg), PIL, the figure and acquisition plots, the integrals of the
kinematics figure, rerun (as :func:`vibroscope.viewers.rerun_recording.preload` does, without
pandas) with the recording code, and one small figure drawn
(:func:`~vibroscope.viewers.drawing_server.warm_up`); the server then ends without tearing the
interpreter down. Importing it has these effects and nothing else; no other module imports it."""

import atexit
import contextlib
import os

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
# the server holds nothing to flush or clean up: when its lifeline closes it ends at once, not after
# the ~0.25 s it takes to tear down matplotlib and rerun (registered last, so run first; forked
# workers end with os._exit and never run atexit handlers)
atexit.register(os._exit, 0)
