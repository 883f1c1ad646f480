"""The plotting backend behind every result's ``.plot()``.

A result object (a spectrum, an FRF, a mode set, a gap report, an instrument's response) does not
import the figures that draw it: its ``.plot()`` calls :func:`draw` with the name of a figure, and
:func:`draw` finds that function in the plotting backend, a module named by string and imported on
first use. The default backend is :mod:`vibroscope.viewers` (matplotlib); another one (a
module offering functions of the same names and signatures) is chosen with :func:`set_backend` or
the environment variable ``VIBROSCOPE_PLOTTING_BACKEND``. This is the pattern of pandas'
``DataFrame.plot`` (``pandas.options.plotting.backend``, pandas 0.25): the computing layers stay
below the viewers, and the import contracts in ``pyproject.toml`` hold with no exception.
"""

from __future__ import annotations

import os
from importlib import import_module
from types import ModuleType
from typing import Any

__all__ = ["DEFAULT_BACKEND", "draw", "get_backend", "set_backend"]

#: The module that draws results unless another is chosen.
DEFAULT_BACKEND = "vibroscope.viewers"

_backend: str = os.environ.get("VIBROSCOPE_PLOTTING_BACKEND") or DEFAULT_BACKEND


def set_backend(name: str | None) -> None:
    """Choose the plotting backend by module name (None: back to :data:`DEFAULT_BACKEND`).

    Parameters
    ----------
    name : str or None
        An importable module offering the figure functions :func:`draw` asks for
        (``plot_spectrum``, ``plot_frf``, …, see :mod:`vibroscope.viewers`).

    Raises
    ------
    ModuleNotFoundError
        If `name` cannot be imported (checked now, not at the first plot).
    """
    global _backend
    name = name or DEFAULT_BACKEND
    import_module(name)
    _backend = name


def get_backend() -> ModuleType:
    """The plotting backend module now in use (imported on this call).

    Returns
    -------
    module
        The backend module (default :data:`DEFAULT_BACKEND`).

    Raises
    ------
    ModuleNotFoundError
        If the chosen backend cannot be imported (the message says how to go back to the default).
    """
    try:
        return import_module(_backend)
    except ModuleNotFoundError as exc:
        raise ModuleNotFoundError(
            f"plotting backend {_backend!r} cannot be imported ({exc}); set "
            f"VIBROSCOPE_PLOTTING_BACKEND or call vibroscope._plotting.set_backend(None) "
            f"for the default {DEFAULT_BACKEND!r}") from exc


def draw(figure: str, result: Any, *args: Any, **kwargs: Any) -> Any:
    """Draw `result` with the backend's function `figure`; returns what that function returns.

    Parameters
    ----------
    figure : str
        The figure function's name in the backend (``"plot_spectrum"``, ``"plot_frf"``, …).
    result : object
        The result to draw, passed first.
    *args, **kwargs
        Passed on to the figure function.

    Returns
    -------
    object
        What the backend's figure function returns (an Axes, a Figure or a list of paths).

    Raises
    ------
    AttributeError
        If the backend offers no function named `figure` (the message names the backend).
    """
    backend = get_backend()
    fn = getattr(backend, figure, None)
    if fn is None:
        raise AttributeError(f"plotting backend {backend.__name__!r} has no figure {figure!r} "
                             f"(needed to draw a {type(result).__name__})")
    return fn(result, *args, **kwargs)
