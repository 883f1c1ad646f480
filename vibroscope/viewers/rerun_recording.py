"""The recording stream of an analysis: rerun imported ahead of time, an explicit
:class:`rerun.RecordingStream` saving to an ``.rrd`` file with its blueprint, and a flush that
Ctrl-C can interrupt.

rerun is imported inside the functions: importing this module never imports it.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["preload", "without_pandas_probe", "open_recording", "flush_recording"]


def preload(*, pandas: bool = True) -> None:
    """Import rerun and what its first recording needs, so that :func:`log_analysis` does not wait
    for it; run in a background thread while an analysis computes
    (:func:`vibroscope.commands._outputs.preload_outputs`). pyarrow imports pandas (when
    installed) on the first array it builds from a list, as the blueprint does: that import is
    done here too, unless `pandas` is False.

    Parameters
    ----------
    pandas : bool, optional
        False: pyarrow's pandas shim is told, once for this process, that pandas is missing,
        so that building an array of a given type from a list does not import pandas only to ask
        whether the list is a pandas object (~0.3 s of the 2-core machine's CPU, a fifth of the
        outputs' imports; a list converted with its type inferred may still import it). For a
        process that hands rerun numpy arrays and lists only, as the command line does; an
        explicit ``import pandas`` (and pyarrow's ``from_pandas``/``to_pandas``) still works
        afterwards. Default True: pyarrow left as it is.
    """
    import pyarrow as pa
    import rerun  # noqa: F401
    import rerun.blueprint  # noqa: F401

    if pandas:
        pa.array([0], type=pa.int8())
    else:
        without_pandas_probe(pa)


def without_pandas_probe(pa) -> None:
    """Build pyarrow's first array from a list while ``import pandas`` fails, so that pyarrow's
    pandas shim records pandas as missing and never imports it to look at a list (it would import
    it, ~0.3 s, on the first ``pa.array(list)``); the import is blocked for that one call only (a
    finder first on ``sys.meta_path`` that raises ImportError for pandas, removed at once). Does
    nothing when pandas is already imported.

    Parameters
    ----------
    pa : module
        ``pyarrow``, imported.
    """
    import sys

    if "pandas" in sys.modules:
        return

    class _NoPandas:
        @staticmethod
        def find_spec(name, path=None, target=None):
            if name == "pandas" or name.startswith("pandas."):
                raise ImportError("pandas is not needed here (vibroscope: pyarrow told it is missing)")
            return None

    finder = _NoPandas()
    sys.meta_path.insert(0, finder)
    try:
        pa.array([0], type=pa.int8())
    finally:
        sys.meta_path.remove(finder)


def open_recording(application_id: str, recording_id: str | None, recording_name: str | None,
                   rrd_path: str | Path, blueprint):
    """An explicit recording stream (never rerun's global one) saving to `rrd_path`.

    Parameters
    ----------
    application_id : str
        The application id of rerun (the mark by which a later run knows the file as its own).
    recording_id : str or None
        Fixed recording id; a random one when None.
    recording_name : str or None
        Shown in the viewer as the recording's name; none when None.
    rrd_path : str or Path
        The ``.rrd`` file (its folder is created).
    blueprint : rerun.blueprint.Blueprint
        Sent as the recording's default blueprint.

    Returns
    -------
    rec : rerun.RecordingStream
        The stream; flush (:func:`flush_recording`) and disconnect it to complete the file.
    path : Path
        `rrd_path`.
    """
    import rerun as rr

    rec = rr.RecordingStream(application_id, recording_id=recording_id)
    if recording_name:
        rec.send_recording_name(recording_name)
    path = Path(rrd_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec.save(str(path), default_blueprint=blueprint)
    return rec, path


def flush_recording(rec, *, step_s: float = 0.25) -> None:
    """Flush a recording in short waits, so that Ctrl-C and SIGTERM are never held by the flush.

    :meth:`rerun.RecordingStream.flush` waits without a timeout by default, inside rerun's native
    code where Python's signal handlers cannot run; here each wait is at most `step_s`, repeated
    until the flush is complete.

    Parameters
    ----------
    rec : rerun.RecordingStream
        The recording.
    step_s : float, optional
        Longest single wait (s); default 0.25.
    """
    while True:
        try:
            rec.flush(timeout_sec=step_s)
            return
        except RuntimeError:  # "Flush timed out - not all log messages were sent": wait on
            continue
