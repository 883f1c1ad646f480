"""The memory budget of ``vibroscope analyse``: how much a log may take when read whole, and how
much reading it whole would take (beyond the budget the log is streamed)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["parse_size", "memory_budget", "whole_read_bytes"]


def parse_size(text: str) -> int:
    """Bytes of a size such as ``1GB``, ``512MB``, ``1.5G``, ``200000`` (powers of 1024).

    Parameters
    ----------
    text : str
        A number with an optional unit K, M, G, T (with or without B, ``iB``).

    Returns
    -------
    int

    Raises
    ------
    ValueError
        If `text` is not such a size or not positive.
    """
    import re

    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([kmgt]?)(i?b)?\s*", str(text), re.I)
    if not m or float(m.group(1)) <= 0:
        raise ValueError(f"{text=} is not a memory size such as 1GB or 512MB")
    return int(float(m.group(1)) * 1024 ** " KMGT".index(m.group(2).upper() or " "))


def memory_budget(max_memory: str | None = None) -> int:
    """The memory (bytes) a log may take when read whole.

    Parameters
    ----------
    max_memory : str, optional
        ``--max-memory`` (:func:`parse_size`); default half the available memory or half the
        address-space limit (``ulimit -v``, ``RLIMIT_AS``), whichever is smaller.

    Returns
    -------
    int

    Raises
    ------
    VibroscopeError
        If `max_memory` is not a size.
    """
    from vibroscope.errors import VibroscopeError

    if max_memory is not None:
        try:
            return parse_size(max_memory)
        except ValueError as exc:
            raise VibroscopeError(f"--max-memory {max_memory}: {exc}") from None
    from vibroscope.io import memory_budget as default_budget

    return default_budget()


def whole_read_bytes(log: Path) -> int:
    """Memory (bytes) that reading `log` whole takes, roughly: the file mapped, plus its chunks
    decompressed (their sizes from the summary; else three times the file), plus the grid.

    Parameters
    ----------
    log : Path
        The MCAP log.

    Returns
    -------
    int
        0 when the file cannot be looked at (the read then says why).
    """
    try:
        size = Path(log).stat().st_size
    except OSError:
        return 0  # the read reports the problem with the file
    try:
        from mcap.reader import SeekingReader

        with open(log, "rb") as fh:
            summ = SeekingReader(fh).get_summary()
        inner = sum(ci.uncompressed_size for ci in summ.chunk_indexes) if summ and summ.chunk_indexes else 3 * size
    except Exception:  # noqa: BLE001 - no usable summary: the rough figure
        inner = 3 * size
    return int(size + 1.5 * inner)
