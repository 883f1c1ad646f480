"""The outputs of an analysis that need only its time series, started while the modes are
identified (issue 20, item 11).

The identification (SSI-COV and its bootstrap, LSCF, ...) runs on one core: on the project's
2-core machine the other core waits for it. :class:`TimeSeriesAhead` puts it to work: called with
the record the modes are identified from (the ``on_signals`` hook of
:func:`vibroscope.pipeline.analyse_signals`), it forks one worker process that integrates the
accelerations (velocity and displacement, for ``kinematics.png`` and the recording: a task of its
own, first, so that the recording need not wait for the figures) and draws ``kinematics.png`` and
``signals.png`` into memory while the analysis goes on. With a drawing server
(:mod:`vibroscope.viewers.drawing_server`) the worker is forked from it, matplotlib already loaded. The outputs then
take what it made instead of computing it again (:meth:`TimeSeriesAhead.kinematics`, and
:func:`vibroscope.viewers.figures.figure_jobs` with ``ahead=``): the same calls on the same data,
so the same integrals and the same PNG bytes.

matplotlib is imported in the worker only; importing this module imports neither matplotlib nor
rerun.
"""

from __future__ import annotations

import io
import sys

from vibroscope.viewers.figures import OwnsWorkerPool

__all__ = ["TimeSeriesAhead", "ACCELERATION_UNITS", "MAX_BYTES"]

#: units of the channels integrated to velocity and displacement (those of ``write_outputs``)
ACCELERATION_UNITS = ("m/s^2", "m/s²")

#: largest record (bytes of its samples) worked on ahead: the integrals come back to the parent
#: pickled (twice the record's size in the worker, in the pipe and in the parent for a moment), so a
#: record near the memory budget is left to the outputs, which integrate it in place
MAX_BYTES = 256 * 2**20

#: the integrals of the worker's last integration task, kept in the worker for the kinematics
#: figure that follows it (one worker runs the tasks in order)
_STASH: dict = {}


def _png(fig) -> bytes:
    """The PNG bytes :func:`vibroscope.viewers.figures.save_figure` writes for `fig`."""
    from vibroscope.viewers.figures import save_figure

    buf = io.BytesIO()
    save_figure(getattr(fig, "figure", fig), buf)
    return buf.getvalue()


def _integrate(acc):
    """Worker: (velocity, displacement) of the accelerations `acc`, kept for :func:`_kinematics_png`."""
    from vibroscope.spectral.integration import velocity_and_displacement

    vel, disp = velocity_and_displacement(acc)
    _STASH["kinematics"] = (acc, vel, disp)
    return vel, disp


def _kinematics_png() -> bytes:
    """Worker: the PNG bytes of ``kinematics.png`` of the integration task run before it."""
    from vibroscope.viewers.acquisition import plot_kinematics

    acc, vel, disp = _STASH.pop("kinematics")
    return _png(plot_kinematics(acc, integrals=(vel, disp)))


def _signals(sig) -> bytes:
    """Worker: the PNG bytes of ``signals.png`` of `sig`."""
    from vibroscope.viewers.figures import plot_signals

    return _png(plot_signals(sig))


class TimeSeriesAhead(OwnsWorkerPool):
    """Integrals and time-series figures of an analysed record, made in a worker process while the
    modes are identified.

    Pass :meth:`start` as ``on_signals`` to :func:`vibroscope.pipeline.analyse_signals` (through
    :func:`vibroscope.commands.analyse.analyse_log`); the outputs then ask :meth:`holds` whether
    the work was done for their record and take it (:meth:`kinematics`, :meth:`drawn`). Where
    ``fork`` is not available (not Linux), :meth:`start` does nothing and the outputs compute
    everything themselves. Use it as a context manager, or call :meth:`close`: the worker is
    stopped on an error or Ctrl-C.

    Parameters
    ----------
    figures : bool
        Draw ``kinematics.png`` and ``signals.png``.
    kinematics : bool
        Integrate the accelerations (for the figure or the recording).
    max_bytes : int, optional
        Largest record (bytes of its samples) worked on ahead; default :data:`MAX_BYTES`
        (256 MiB). A larger one is left to the outputs.
    server : multiprocessing context, optional
        A running drawing server's context (:func:`vibroscope.viewers.drawing_server.context`):
        the worker is forked from it, with matplotlib loaded there; default None, forked from
        this process. Either way the record is pickled to the worker and the integrals back.
    """

    def __init__(self, *, figures: bool, kinematics: bool, max_bytes: int = MAX_BYTES, server=None):
        self._server = server
        self._figures, self._kin = bool(figures), bool(kinematics)
        self._max_bytes = int(max_bytes)
        self._pool = None
        self._results: dict = {}
        self._signals = None
        self._acc: list[str] = []

    def start(self, signals, outputs) -> None:
        """Fork the worker and hand it the record (the ``on_signals`` hook).

        Call it when no other thread holds a lock the worker needs (the background imports of
        :func:`vibroscope.commands._outputs.preload_outputs` joined first).

        Parameters
        ----------
        signals : Signals
            The record the modes are identified from (``Analysis.signals``).
        outputs : sequence of str
            The response channels; those in m/s² are integrated.
        """
        if (self._signals is not None or not (self._figures or self._kin) or not sys.platform.startswith("linux")
                or signals.data.nbytes > self._max_bytes):
            return
        acc = [c for c, u in zip(signals.channels, signals.units) if c in outputs and u in ACCELERATION_UNITS]
        tasks = []  # run in this order by the one worker: the integrals first, for the recording
        if acc:
            tasks.append(("kinematics", _integrate, (signals.select(acc),)))
            if self._figures:
                tasks.append(("kinematics_png", _kinematics_png, ()))
        if self._figures and self._server is None:  # with a drawing server, the figure pool draws it
            # after the analysis, beside the others: this worker's kinematics figure is the longest
            tasks.append(("signals", _signals, (signals,)))
        if not tasks:
            return
        import multiprocessing

        from vibroscope.viewers.figures import quiet_worker

        self._signals, self._acc = signals, acc
        if self._server is None:
            self._pool = multiprocessing.get_context("fork").Pool(1, initializer=quiet_worker)
        else:  # forked by the drawing server (waits for it if it is still importing)
            from vibroscope.viewers.figures import server_pool

            self._pool = server_pool(self._server, 1)
        self._results = {name: self._pool.apply_async(fn, args) for name, fn, args in tasks}

    def holds(self, signals, acc) -> bool:
        """Whether the work was started for this record and these acceleration channels.

        Parameters
        ----------
        signals : Signals
            The analysis' record (the very object given to :meth:`start`).
        acc : sequence of str
            The acceleration channels the outputs integrate.

        Returns
        -------
        bool
        """
        return self._signals is not None and signals is self._signals and list(acc) == self._acc

    def kinematics(self):
        """The velocity and displacement of the accelerations, once integrated (waits for them).

        Returns
        -------
        (Signals, Signals) or None
            :func:`vibroscope.spectral.integration.velocity_and_displacement` of the acceleration
            channels; None when there are none.

        Raises
        ------
        Exception
            The worker's error, as raised there.
        """
        res = self._results.get("kinematics")
        if res is None:
            return None
        vel, disp = res.get()
        return vel, disp

    def drawn(self, signals) -> dict:
        """The figures drawn for `signals`, by name (``"kinematics"``, ``"signals"``), each a
        :class:`vibroscope.viewers.figures.DrawnFigure` (its PNG bytes, waited for when written).

        Parameters
        ----------
        signals : Signals
            The record of the figures asked for; nothing is returned for another one.

        Returns
        -------
        dict
        """
        from vibroscope.viewers.figures import DrawnFigure

        if self._signals is None or signals is not self._signals or not self._figures:
            return {}
        out = {}
        if "kinematics_png" in self._results:
            out["kinematics"] = DrawnFigure(self._results["kinematics_png"].get)
        if "signals" in self._results:
            out["signals"] = DrawnFigure(self._results["signals"].get)
        return out
