"""Command-line option values shared by several commands, parsed once (commands import this
module, never each other)."""

from __future__ import annotations

from vibroscope.errors import VibroscopeError

__all__ = ["select_frequencies"]


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
