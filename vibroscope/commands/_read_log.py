"""A log read for ``vibroscope analyse`` and ``vibroscope modal``: the response channels and the
force input chosen (whole read, or block by block for ``--stream`` and ``--connect``)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["analyse_log", "looks_for_input", "grid_input"]


def analyse_log(log: Path, *, input=None, outputs=None, fs=None, progress=False, find_input=False, max_memory=None,
                **kw):
    """Read `log` and run :func:`vibroscope.pipeline.analyse_signals`; returns the Analysis.

    Without `outputs`, the responses are chosen by :func:`vibroscope.io.select.auto_channels`
    (Imu accelerations; else the measurement fields of the busiest topic), and the choice and
    what was skipped (undecodable channels by name) go into the warnings; the log is then
    scanned once (:class:`vibroscope.io.LogIndex`) for both the choice and the read.

    With `find_input` and no `input`, the log's one force-like channel that moves
    (:func:`vibroscope.io.select.find_force_input`: a Wrench force, a field in N, or one named
    force/command/input, outside the responses' topics) is the input; the line saying so (or why
    none was taken) is ``signals.meta["input_choice"]``, printed by :func:`vibroscope.commands._report.report_text` and
    written to the summary JSON.

    Parameters
    ----------
    log : Path
        The MCAP log.
    input : str, optional
        The force channel (message path); without it the analysis is output-only.
    outputs : sequence of str, optional
        The response channels; default: chosen automatically (see above), at most
        ``MAX_AUTO_CHANNELS`` varying fields when no IMU is found.
    fs : float, optional
        Rate in Hz to resample onto (:func:`vibroscope.io.read_mcap`); default the highest
        topic rate.
    progress : bool, optional
        Show a progress bar while reading; default False.
    find_input : bool, optional
        Without `input`, take the log's one force-like channel as the input (see above);
        default False (output-only without `input`). Only for the methods that use an input
        (:func:`vibroscope.modal.methods.uses_input`).
    max_memory : int, optional
        Memory budget in bytes for reading the log (:func:`vibroscope.io.read_mcap`); default
        half the available memory.
    **kw
        Passed to :func:`vibroscope.pipeline.analyse_signals` (``nperseg``, ``fmin``, ...).

    Returns
    -------
    Analysis
    """
    from vibroscope.errors import VibroscopeError
    from vibroscope.io import LogIndex, read_mcap
    from vibroscope.io.select import MAX_AUTO_CHANNELS, auto_channels, find_force_input, moving_channels
    from vibroscope.pipeline import analyse_signals

    notes, fallback, source, choice = [], False, log, None
    from vibroscope.modal.methods import uses_input

    find_input = find_input and input is None and uses_input(kw.get("method", "auto"))
    if outputs is None or find_input:  # scan the log once: the index serves the choices and the read
        source = LogIndex.open(log, progress=progress, max_memory=max_memory)
    if find_input:
        resp = {source.topic_of(c).topic for c in outputs or ()}
        try:
            found = find_force_input(source, exclude_topics=resp)
            input, choice = found.channel, found.line() or None
        except VibroscopeError as exc:  # the search never stops an output-only analysis
            choice = f"no force input looked for: {exc}"
    if outputs is None:
        # the input's topic holds the force, not a response
        sel = auto_channels(source, exclude_topics=(input.split(".", 1)[0],) if input else ())
        notes.append(f"channels chosen automatically: {sel.reason}")
        notes += [f"{what}: skipped: {why}" for what, why in sel.skipped]
        outputs, fallback = [c for c in sel.channels if c != input], sel.fallback
    sig = read_mcap(source, [input, *outputs] if input else list(outputs), fs=fs, progress=progress,
                    max_memory=max_memory)
    if sig.n_samples < 16:  # not one Welch segment of the shortest length
        raise ValueError(f"the log is too short to analyse: {sig.n_samples} samples on the common grid "
                         f"({sig.duration:.3g} s at {sig.fs:g} Hz); at least 16 are needed")
    if fallback:  # automatic non-IMU choice: keep the fields that move, at most MAX_AUTO_CHANNELS
        moving = moving_channels(outputs, [sig[c] for c in outputs])  # NaN marks a gap, not a value
        if len(moving) > MAX_AUTO_CHANNELS:
            notes.append(f"{len(moving) - MAX_AUTO_CHANNELS} varying fields beyond the first {MAX_AUTO_CHANNELS} "
                         f"not analysed (from {moving[MAX_AUTO_CHANNELS]}); choose with --outputs")
        if len(outputs) > len(moving):
            notes.append(f"{len(outputs) - len(moving)} constant fields not analysed")
        sig = sig.select(([input] if input else []) + moving[:MAX_AUTO_CHANNELS])
    if notes:
        sig = sig.with_meta(warnings=notes + list(sig.meta.get("warnings", [])))
    if choice:
        sig = sig.with_meta(input_choice=choice)
    return analyse_signals(sig, input=input, **kw)


def looks_for_input(args) -> bool:
    """Whether ``analyse`` takes the log's force-like channel as the input: no ``--input``, no
    ``--output-only``, and a method that uses an input (as :func:`analyse_log` with `find_input`).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    bool
    """
    from vibroscope.modal.methods import uses_input

    return (not getattr(args, "input", None) and not getattr(args, "output_only", False)
            and uses_input(getattr(args, "method", "auto")))


def grid_input(log: Path, outputs=None, fs=None) -> tuple[str | None, str | None]:
    """The force input of a log read block by block (``--stream``, ``--connect``): the one force-like
    channel that moves in the first and last chunks of its topic
    (:meth:`vibroscope.io.blocks.LogGrid.force_input`), as :func:`analyse_log` finds it in a whole
    read.

    Parameters
    ----------
    log : Path
        The MCAP log.
    outputs : sequence of str, optional
        The response channels (their topics are never the input); default chosen automatically.
    fs : float, optional
        Grid rate in Hz; default the highest topic rate.

    Returns
    -------
    tuple of (str or None, str or None)
        (the input's message path, or None; the report's line saying what was taken or why none
        was, or None when the log holds no force-like field).
    """
    from vibroscope.errors import VibroscopeError
    from vibroscope.io.blocks import open_grid

    try:
        found = open_grid(log, outputs, fs=fs).force_input(exclude_channels=outputs or ())
    except (VibroscopeError, ValueError) as exc:  # the search never stops an output-only analysis
        return None, f"no force input looked for: {exc}"
    return found.channel, found.line() or None
