"""Imported once by the drawing server (:mod:`vibroscope.viewers.drawing_server`) before it forks the
workers: matplotlib (Agg), PIL, the figure and acquisition plots, the integrals of the
kinematics figure, rerun (as :func:`vibroscope.viewers.rerun_recording.preload` does, without
pandas) with the recording code, and one small figure drawn
(:func:`~vibroscope.viewers.drawing_server.warm_up`). Importing it has these effects and nothing
else; no other module imports it."""

import contextlib

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
