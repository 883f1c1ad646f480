"""The drawing server of ``vibroscope analyse``: one process, started with the command, that imports
matplotlib (Agg), PIL and the figure code once, on the otherwise idle core, while the command
imports its numerics and reads the log; the figure workers are forked from it when there is
something to draw, so that they start with all of it loaded (issue 20, item 11).

Before, the command imported matplotlib in a background thread of its own process, where the
imports (~0.6 s of CPU on the project's 2-core machine) shared one interpreter lock with the
analysis and delayed it by as much; and the workers, forked from the command, inherited them.
Now the command itself never imports matplotlib: the work handed to the workers is pickled
(``functools.partial`` of the plotting functions with their data: the results are small, a
record of 3 × 5e5 samples pickles in ~10 ms).

This is Python's own ``forkserver`` start method (:mod:`multiprocessing`, Linux):
:mod:`vibroscope.viewers.drawing_preload` is its preload, imported once in the server;
:func:`start` starts it, :func:`context` gives the context whose pools fork from it
(:func:`vibroscope.viewers.figures.server_pool`). Importing
this module imports neither matplotlib nor rerun.
"""

from __future__ import annotations

import sys

__all__ = ["start", "stop", "context", "warm_up", "main_is_importable", "PRELOAD"]

#: the module the server imports before it forks any worker
PRELOAD = "vibroscope.viewers.drawing_preload"

_CONTEXT: list = []


def warm_up() -> None:
    """Draw one small figure with text (the fonts and the text layout loaded) so that every worker
    forked afterwards starts with them."""
    import io

    from vibroscope.viewers.figures import pyplot, save_figure

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(2, 1.5), layout="constrained")
    ax.plot([0.0, 1.0], [0.0, 1.0], label="a")
    ax.set_xlabel("frequency [Hz]")
    ax.set_title("warm-up")
    ax.legend()
    save_figure(fig, io.BytesIO())


def start() -> bool:
    """Start the drawing server (once per process; Linux only). Returns whether it runs.

    The server is a fresh interpreter that imports :data:`PRELOAD` (matplotlib with Agg, PIL,
    the figure and acquisition plots, then :func:`warm_up`) and then forks a worker for each process asked of
    :func:`context`; it ends when this process ends. Call it early: the imports run while this
    process works on.

    Returns
    -------
    bool
        False where ``forkserver`` is not available (not Linux), where this process's main module
        is not known to be safe to import again (:func:`main_is_importable`), or where the server
        could not be started; the callers then fork their workers from this process as before.
    """
    if _CONTEXT:
        return True
    if not sys.platform.startswith("linux") or not main_is_importable():
        return False
    import multiprocessing
    from multiprocessing import forkserver

    try:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload([PRELOAD])
        forkserver.ensure_running()
    except Exception:  # pragma: no cover - no server: the workers are forked from this process
        return False
    _CONTEXT.append(ctx)
    return True


def main_is_importable() -> bool:
    """Whether this process's ``__main__`` may be imported by the server's workers without running
    anything: each worker of a ``forkserver`` (or ``spawn``) context first imports the parent's main
    module under another name (:mod:`multiprocessing`, "Safe importing of main module"), which
    would run again a script that calls the command without an ``if __name__ == "__main__":``
    guard. True for the ``vibroscope`` command (the console script pip writes, or ``python -m
    vibroscope.cli``) and for ``python -c`` or an interactive session (nothing to import); False
    for any other script (its workers are then forked from the process itself, as before).

    Returns
    -------
    bool
    """
    main = sys.modules.get("__main__")
    name = getattr(getattr(main, "__spec__", None), "name", None)
    if name is not None:
        return name in ("vibroscope.cli", "vibroscope.__main__")
    path = getattr(main, "__file__", None)
    if path is None:
        return True
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    return "from vibroscope.cli import main" in head and any(
        g in head for g in ("if __name__ == '__main__':", 'if __name__ == "__main__":'))


def stop(*, wait: bool = True) -> None:
    """Stop the drawing server, if :func:`start` started it.

    The server ends by itself when this process ends (and its workers with their pools); with
    `wait`, its lifeline is closed now and this process waits for it: no process is left behind
    the command, and the CPU time of the server and its workers becomes part of this process's
    children's (``getrusage(RUSAGE_CHILDREN)``, as ``benchmarks/analyse_outputs.py`` reads it).

    Parameters
    ----------
    wait : bool, optional
        Default True. Give False after an error or Ctrl-C: a worker still running would hold the
        server's lifeline open, and the wait would last until it ends.
    """
    if not _CONTEXT:
        return
    _CONTEXT.clear()
    if not wait:
        return
    import contextlib
    from multiprocessing import forkserver

    # the stdlib's own stop (closes the server's lifeline and waits for it; used by its tests)
    halt = getattr(getattr(forkserver, "_forkserver", None), "_stop", None)
    if halt is not None:
        with contextlib.suppress(Exception):
            halt()


def context():
    """The ``forkserver`` context of the running drawing server.

    Returns
    -------
    multiprocessing.context.ForkServerContext or None
        None when :func:`start` was not called (or failed) in this process, or after :func:`stop`.
    """
    return _CONTEXT[0] if _CONTEXT else None

