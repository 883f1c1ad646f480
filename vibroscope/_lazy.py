"""The one lazy-import helper of the package ``__init__`` modules (PEP 562 ``__getattr__``).

A package lists the names it offers and the module that defines each; the module is imported on
the first access of one of its names, so that ``import vibroscope`` (or ``vibroscope.io``,
``vibroscope.viewers``) loads none of the heavy edges (rerun, matplotlib, mcap, dask, numba).
"""

from __future__ import annotations

import sys
from importlib import import_module
from importlib.util import find_spec
from typing import Any, Callable, Mapping

__all__ = ["lazy_attributes"]


def lazy_attributes(package: str, names: Mapping[str, str], *,
                    submodules: bool = False) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module-level ``__getattr__`` and ``__dir__`` of a package whose names load on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    names : mapping of str to str
        Attribute name -> the module that defines it: absolute (``"vibroscope.spectral"``) or
        relative to `package` (``".figures"``).
    submodules : bool, optional
        Also resolve a submodule's name to the submodule (as it is once anything has imported
        it), before `names`; default False.

    Returns
    -------
    __getattr__ : callable
        ``__getattr__(name)``: the object, cached in the package's namespace (the next access does
        not come here); raises ``AttributeError("module 'pkg' has no attribute 'x'")`` for a name
        it does not know.
    __dir__ : callable
        The package's globals and `names`, sorted.

    Examples
    --------
    In a package's ``__init__.py``::

        __getattr__, __dir__ = lazy_attributes(__name__, {"plot_frf": ".figures"})
    """
    table = dict(names)

    def __getattr__(name: str) -> Any:
        if submodules and not name.startswith("__") and find_spec(f"{package}.{name}") is not None:
            return import_module(f"{package}.{name}")
        mod = table.get(name)
        if mod is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(import_module(mod, package), name)
        vars(sys.modules[package])[name] = value  # cache: the next access skips __getattr__
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(table))

    return __getattr__, __dir__
