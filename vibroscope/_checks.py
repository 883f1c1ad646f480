"""Small checks and helpers shared by every room of vibroscope (imports nothing of ours).

- :func:`check_option`: one uniform ``ValueError`` for an option value that is not allowed
  (MNE-Python's ``_check_option``).
- :func:`read_only`: a private, read-only copy of an array, as results store their arrays
  (scipy's ``ShortTimeFFT`` returns read-only windows the same way).
- :func:`atomic_file`: write one file under a temporary name, renamed when complete.
- :func:`jsonable`: numpy values and containers as plain JSON values (NaN/Inf as null).
- :class:`LazyChoices`: allowed values read from a registry on first use (``argparse`` choices
  that do not import the room that holds the registry until they are checked or shown).
- :class:`UnpacksAsTuple`, :func:`axis_summary`, :func:`names_summary`: what the result types of
  the spectral and modal rooms share (tuple behaviour, the pieces of their ``repr``).
"""

from __future__ import annotations

import contextlib
import importlib
import os
import secrets
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

__all__ = ["check_option", "read_only", "atomic_file", "jsonable", "LazyChoices", "UnpacksAsTuple", "axis_summary",
           "names_summary"]


class LazyChoices(Sequence):
    """The tuple ``module.name``, imported on first use.

    ``argparse`` reads its ``choices`` only to check a value given on the command line and to
    format the help, so a parser built with these does not import the registry's room (and its
    numerical libraries) when the option is not used.

    Parameters
    ----------
    module : str
        The module that holds the values, e.g. ``'vibroscope.modal.methods'``.
    name : str
        The tuple's name in it, e.g. ``'METHOD_CHOICES'``.

    Examples
    --------
    >>> c = LazyChoices("vibroscope.spectral.kinds", "FRF_KINDS")
    >>> "mobility" in c, list(c)
    (True, ['accelerance', 'mobility', 'receptance'])
    """

    def __init__(self, module: str, name: str) -> None:
        self.module, self.name, self._values = module, name, None

    def _get(self) -> tuple:
        if self._values is None:
            self._values = tuple(getattr(importlib.import_module(self.module), self.name))
        return self._values

    def __getitem__(self, i):
        return self._get()[i]

    def __len__(self) -> int:
        return len(self._get())

    def __contains__(self, value: object) -> bool:
        return value in self._get()

    def __repr__(self) -> str:
        return f"LazyChoices({self.module}.{self.name})"


@contextlib.contextmanager
def atomic_file(path: str | Path) -> Iterator[Path]:
    """A temporary path beside `path`, renamed to `path` when the block completes.

    Parameters
    ----------
    path : str or Path
        The file to write; replaced if it exists.

    Yields
    ------
    Path
        ``.NAME.PID-XXXXXXXX.part`` in the same directory; the caller creates and writes it.
        On any exception (``KeyboardInterrupt`` included) it is removed and `path` is left as
        it was; the rename (``os.replace``) is atomic on one file system.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.part")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def check_option(name: str, value: Any, allowed: tuple) -> None:
    """Raise one uniform ``ValueError`` when `value` is not one of `allowed`.

    Parameters
    ----------
    name : str
        The parameter's name, as the caller spells it.
    value : object
        The value given.
    allowed : tuple
        The allowed values.

    Raises
    ------
    ValueError
        ``"Invalid value for the 'name' parameter. Allowed values are ..., but got ... instead."``
    """
    if value not in allowed:
        raise ValueError(
            f"Invalid value for the {name!r} parameter. Allowed values are "
            f"{', '.join(repr(a) for a in allowed)}, but got {value!r} instead."
        )


def read_only(a: Any, dtype: Any = None) -> np.ndarray:
    """A copy of `a` as an ndarray (of `dtype` when given) that cannot be written to.

    Parameters
    ----------
    a : array_like
        The values.
    dtype : data-type, optional
        Converted to this type; default inferred from `a`.

    Returns
    -------
    ndarray
        A new array with ``flags.writeable`` False; later changes to `a` do not reach it.
    """
    out = np.array(a, dtype=dtype, copy=True)
    out.flags.writeable = False
    return out


def jsonable(v: Any) -> Any:
    """`v` with numpy scalars and arrays as Python numbers and lists, tuples as lists, dict keys
    as strings and non-finite floats as None (JSON ``null``), recursively.

    Parameters
    ----------
    v : object
        A value of a summary (dict, list, tuple, numpy scalar or array, number, str, ...).

    Returns
    -------
    object
        A value :func:`json.dumps` writes as strict JSON (no ``NaN``).

    Examples
    --------
    >>> jsonable({"f": np.array([1.5, np.nan]), 2: (np.int64(3),)})
    {'f': [1.5, None], '2': [3]}
    """
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return jsonable(v.tolist())  # NaN entries become null too
    if isinstance(v, float) and not np.isfinite(v):
        return None
    return v


def axis_summary(frequencies: np.ndarray) -> str:
    """``"129 lines, 0–256 Hz"`` for a frequency axis (the piece of a result's ``repr``).

    Parameters
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Frequency axis in Hz, ascending.

    Returns
    -------
    str
        ``"0 lines"`` for an empty axis.

    Examples
    --------
    >>> import numpy as np
    >>> axis_summary(np.linspace(0.0, 256.0, 129))
    '129 lines, 0–256 Hz'
    """
    if frequencies.size == 0:
        return "0 lines"
    return f"{frequencies.size} lines, {frequencies[0]:.4g}–{frequencies[-1]:.4g} Hz"


def names_summary(names: Sequence[str], k: int = 3) -> str:
    """At most `k` names, then the count of the others (the piece of a result's ``repr``).

    Parameters
    ----------
    names : sequence of str
        Channel (or input/output) names.
    k : int, optional
        Most names written out; default 3.

    Returns
    -------
    str

    Examples
    --------
    >>> names_summary(["/imu/a.x", "/imu/b.x", "/imu/c.x", "/imu/d.x"], k=2)
    "['/imu/a.x', '/imu/b.x', … +2]"
    """
    head = ", ".join(repr(n) for n in names[:k])
    return f"[{head}{f', … +{len(names) - k}' if len(names) > k else ''}]"


class UnpacksAsTuple:
    """Tuple behaviour of a result: it unpacks, has a length and indexes like the tuple of its
    ``_tuple_fields`` (what the function returned before it returned a result object)."""

    _tuple_fields = ()

    def __iter__(self) -> Iterator[Any]:
        return iter(tuple(getattr(self, name) for name in self._tuple_fields))

    def __len__(self) -> int:
        return len(self._tuple_fields)

    def __getitem__(self, i):
        return tuple(self)[i]
