"""Command-line option values shared by several commands, parsed once (commands import this
module, never each other)."""

from __future__ import annotations

from vibroscope.errors import VibroscopeError

__all__ = ["select_frequencies", "check_options"]


def select_frequencies(spec: str | None) -> list[float] | None:
    """The ``--select`` option of ``vibroscope analyse`` and ``vibroscope modal``.

    Parameters
    ----------
    spec : str or None
        ``'auto'`` (or None) for the automatic choice, else frequencies in Hz separated by ``,``
        or ``;``, e.g. ``'6.5,17.5'``.

    Returns
    -------
    list of float or None
        The frequencies in Hz; None for the automatic choice.

    Raises
    ------
    VibroscopeError
        If an entry is not a number, or none is given, or one is not positive (names the option).

    Examples
    --------
    >>> select_frequencies("6.5; 17.5")
    [6.5, 17.5]
    """
    if spec is None or spec.strip().lower() == "auto":
        return None
    try:
        fr = [float(x) for x in spec.replace(";", ",").split(",") if x.strip()]
    except ValueError:
        raise VibroscopeError(f"--select {spec!r}: expected 'auto' or frequencies in Hz such as 6.5,17.5") from None
    if not fr or any(f <= 0 for f in fr):
        raise VibroscopeError(f"--select {spec!r}: frequencies must be positive (Hz)")
    return fr


def check_options(args) -> None:
    """Refuse non-finite or non-positive numbers in the options of ``analyse`` and ``modal`` before any work.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Raises
    ------
    VibroscopeError
        If ``--output-only`` meets ``--input``, a number is not positive and finite, or ``--fmax`` or
        an ``--ods`` frequency lies above the Nyquist frequency of ``--fs`` (the option named).
    """
    import math

    if getattr(args, "output_only", False) and getattr(args, "input", None):
        raise VibroscopeError(f"--output-only and --input {args.input}: give one of them")
    for opt in ("fs", "fmin", "fmax", "nperseg", "n_modes", "df"):
        v = getattr(args, opt, None)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise VibroscopeError(f"--{opt.replace('_', '-')} {v:g}: must be a positive, finite number")
    if getattr(args, "fs", None) is not None and getattr(args, "fmax", None) is not None and args.fmax > args.fs / 2:
        raise VibroscopeError(f"--fmax {args.fmax:g}: above the Nyquist frequency {args.fs / 2:g} Hz of --fs {args.fs:g}")
    for f in getattr(args, "ods", None) or ():
        if not (math.isfinite(f) and f > 0):
            raise VibroscopeError(f"--ods {f:g}: frequencies must be positive and finite (Hz)")
        if getattr(args, "fs", None) is not None and f > args.fs / 2:
            raise VibroscopeError(f"--ods {f:g}: above the Nyquist frequency {args.fs / 2:g} Hz of --fs {args.fs:g}")
