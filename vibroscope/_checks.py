"""Small checks and helpers shared by every room of vibroscope (imports nothing of ours).

- :func:`check_option`: one uniform ``ValueError`` for an option value that is not allowed
  (MNE-Python's ``_check_option``).
- :func:`read_only`: a private, read-only copy of an array, as results store their arrays
  (scipy's ``ShortTimeFFT`` returns read-only windows the same way).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["check_option", "read_only"]


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
