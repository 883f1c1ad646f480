"""Every public function and class of vibroscope documents each of its parameters (numpydoc).

In the spirit of python-control's ``control/tests/docstrings_test.py``: the test walks every
module of the package (:func:`pkgutil.walk_packages`), takes the names of its ``__all__`` that
are functions or classes defined in vibroscope, and checks

- that each has a docstring, with a ``Parameters`` section when it takes parameters;
- that each parameter is listed in a numpydoc section (``Parameters``, ``Other Parameters``, or,
  for a class, ``Attributes``, or the ``__init__`` docstring): a line ``name : type`` (or
  ``name1, name2 : type``, or ``name`` alone) at the left margin of the section.

Classes are checked for their constructor's parameters and for those of each public method
(and class/static method) defined in the class body. ``*args``, ``**kwargs`` and parameters
whose name starts with ``_`` are not required; nor are the constructor parameters of exceptions
and enums. An object re-exported by a package is checked once, under its shortest public name
(``vibroscope.spectral.welch``, not ``vibroscope.spectral.estimators.welch``; the curated
top-level names of :mod:`vibroscope` come last, so not ``vibroscope.welch`` either). The CLI's
``vibroscope.commands`` modules are included: their ``__all__`` is public too.

Known gaps are listed in :data:`UNDOCUMENTED` and marked ``xfail(strict=True)``: documenting one
makes its test pass and fail the run until the entry is removed, so the list stays exact.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
from collections.abc import Iterator

import pytest

import vibroscope

# Modules that need an optional dependency may be skipped when it is missing (the [rerun] and
# [dask] extras); any other import error fails test_every_module_imports.
OPTIONAL = ("rerun", "dask")

# Known gaps, public name -> parameters not (yet) documented; ``None``: the object has no
# docstring, or none with a Parameters section. Each entry is an xfail(strict=True) test.
# Regenerate with ``python tests/test_docstrings.py`` (prints this dict for the current tree).
# BEGIN UNDOCUMENTED
UNDOCUMENTED_BY_OBJECT: dict[str, tuple[str | None, ...]] = {
}
# END UNDOCUMENTED
UNDOCUMENTED = {(q, p) for q, ps in UNDOCUMENTED_BY_OBJECT.items() for p in ps}

SECTIONS = ("Parameters", "Other Parameters", "Attributes")


def _walk() -> tuple[dict[str, object], dict[str, str]]:
    modules, failed = {"vibroscope": vibroscope}, {}
    for info in pkgutil.walk_packages(vibroscope.__path__, "vibroscope."):
        try:
            modules[info.name] = importlib.import_module(info.name)
        except ImportError as exc:
            failed[info.name] = f"{type(exc).__name__}: {exc}"
    return modules, failed


MODULES, IMPORT_FAILURES = _walk()


def _public_objects() -> dict[str, object]:
    """Shortest public name -> function or class, over every module's ``__all__``."""
    found: dict[int, tuple[str, object]] = {}
    # the room's name first (vibroscope.spectral.welch), the top-level re-export last
    for modname in sorted(MODULES, key=lambda m: (m == "vibroscope", m.count("."), m)):
        mod = MODULES[modname]
        for name in getattr(mod, "__all__", ()):
            obj = getattr(mod, name)
            if not (inspect.isfunction(obj) or inspect.isclass(obj)):
                continue
            if not getattr(obj, "__module__", "").startswith("vibroscope"):
                continue
            found.setdefault(id(obj), (f"{modname}.{name}", obj))
    return dict(sorted(found.values(), key=lambda kv: kv[0]))


def _methods(cls: type) -> Iterator[tuple[str, object]]:
    for name, attr in vars(cls).items():
        if name.startswith("_"):
            continue
        if isinstance(attr, (classmethod, staticmethod)) or inspect.isfunction(attr):
            yield name, getattr(cls, name)


def _parameters(obj: object) -> list[str]:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):  # a signature Python cannot tell: nothing to check
        return []
    return [
        p.name
        for p in sig.parameters.values()
        if p.name not in ("self", "cls")
        and not p.name.startswith("_")  # a private field (a dataclass cache) is not the caller's
        and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    ]


def documented_names(doc: str) -> tuple[set[str], set[str]]:
    """Names listed in the numpydoc parameter-like sections of `doc`, and the sections found.

    Parameters
    ----------
    doc : str
        A docstring, cleaned by :func:`inspect.getdoc` (left margin at column 0).

    Examples
    --------
    >>> names, sections = documented_names("Sum.\\n\\nParameters\\n----------\\nx, y : float\\n    Terms.\\nz\\n")
    >>> sorted(names), sorted(sections)
    (['x', 'y', 'z'], ['Parameters'])
    """
    lines = doc.splitlines()
    names: set[str] = set()
    sections: set[str] = set()
    section = None
    for i, line in enumerate(lines):
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if line.strip() and re.fullmatch(r"\s*-{3,}\s*", nxt):
            section = line.strip()
            sections.add(section)
            continue
        if section not in SECTIONS or re.fullmatch(r"\s*-{3,}\s*", line) or not line or line[0].isspace():
            continue
        m = re.match(r"^(\*{0,2}[A-Za-z_]\w*(?:\s*,\s*\*{0,2}[A-Za-z_]\w*)*)\s*(?::|$)", line)
        if m:
            names |= {n.strip().lstrip("*") for n in m.group(1).split(",")}
    return names, sections


def _cases() -> Iterator[tuple[str, object, list[str], str]]:
    """(public name, object, its parameters, the docstring text they must be found in)."""
    for qualname, obj in _public_objects().items():
        if inspect.isclass(obj):
            doc = inspect.getdoc(obj) or ""
            init = vars(obj).get("__init__")
            init_doc = (inspect.getdoc(init) or "") if init is not None else ""
            if init_doc and init_doc != doc:
                doc = f"{doc}\n\n{init_doc}"
            # exception and Enum constructors are not the author's to document
            params = [] if issubclass(obj, BaseException) or _is_enum(obj) else _parameters(obj)
            yield qualname, obj, params, doc
            for mname, meth in _methods(obj):
                yield f"{qualname}.{mname}", meth, _parameters(meth), inspect.getdoc(meth) or ""
        else:
            yield qualname, obj, _parameters(obj), inspect.getdoc(obj) or ""


def _is_enum(cls: type) -> bool:
    import enum

    return issubclass(cls, enum.Enum)


CASES = list(_cases())


def _params(qualname: str, pname: str | None):
    marks = (
        [pytest.mark.xfail(strict=True, reason="undocumented (see UNDOCUMENTED)")]
        if (qualname, pname) in UNDOCUMENTED
        else []
    )
    return pytest.param(qualname, pname, marks=marks, id=f"{qualname}-{pname or 'docstring'}")


ITEMS = [_params(q, None) for q, _, _, _ in CASES] + [_params(q, p) for q, _, ps, _ in CASES for p in ps]
BY_NAME = {q: (obj, ps, doc) for q, obj, ps, doc in CASES}


def test_every_module_imports():
    """pkgutil reaches every module; only a missing optional extra may keep one out."""
    bad = {m: e for m, e in IMPORT_FAILURES.items() if not any(o in e for o in OPTIONAL)}
    assert not bad, bad
    if IMPORT_FAILURES:
        pytest.skip(f"optional extras missing: {sorted(IMPORT_FAILURES)}")


def test_the_walk_finds_the_public_api():
    """A sanity check on the walk itself: the curated names and every room are in it."""
    names = set(BY_NAME)
    for expected in ("vibroscope.signals.Signals", "vibroscope.spectral.welch", "vibroscope.modal.ssi_cov",
                     "vibroscope.models.LumpedModel", "vibroscope.gap.diagnose", "vibroscope.io.read_mcap"):
        assert expected in names
    assert len(CASES) > 100


def test_undocumented_list_has_no_stale_entries():
    """Every entry of UNDOCUMENTED names a collected object and parameter (strictness both ways)."""
    collected = {(q, None) for q in BY_NAME} | {(q, p) for q, (_, ps, _) in BY_NAME.items() for p in ps}
    assert not sorted(UNDOCUMENTED - collected, key=str)


def missing() -> dict[str, list[str | None]]:
    """Public name -> its gaps: ``None`` when it has no docstring (or, taking parameters, no
    Parameters section; a class may list its fields as Attributes), then each parameter that no
    section lists."""
    out: dict[str, list[str | None]] = {}
    for qualname, obj, params, doc in CASES:
        names, sections = documented_names(doc)
        wanted = {"Parameters", "Attributes"} if inspect.isclass(obj) else {"Parameters"}
        gaps: list[str | None] = [None] if not doc.strip() or (params and not wanted & sections) else []
        gaps += [p for p in params if p not in names]
        if gaps:
            out[qualname] = gaps
    return out


GAPS = missing()


@pytest.mark.parametrize("qualname, pname", ITEMS)
def test_documented(qualname, pname):
    if pname is None:
        assert None not in GAPS.get(qualname, ()), f"{qualname} has no docstring with a Parameters section"
    else:
        assert pname not in GAPS.get(qualname, ()), f"{qualname}: parameter {pname!r} undocumented"


if __name__ == "__main__":  # print UNDOCUMENTED_BY_OBJECT for the current tree
    import textwrap

    print("UNDOCUMENTED_BY_OBJECT: dict[str, tuple[str | None, ...]] = {")
    room = None
    for qualname, gaps in sorted(missing().items()):
        if qualname.split(".")[1] != room:
            room = qualname.split(".")[1]
            print(f"    # vibroscope.{room}")
        items = ", ".join("None" if g is None else f'"{g}"' for g in gaps) + ("," if len(gaps) == 1 else "")
        print(textwrap.fill(f'"{qualname}": ({items}),', 108, initial_indent="    ", subsequent_indent="        ",
                            break_on_hyphens=False, break_long_words=False))
    print("}")
