"""Each curated name of :mod:`vibroscope` (its ``__all__``: the lazily loaded ``_LAZY`` table,
:class:`Signals` and the exceptions)
has an ``Examples`` section whose doctest recovers a known number, and the doctest passes.

The same doctests also run in the whole-suite run (``--doctest-modules`` over the package in
``pyproject.toml``); this test is the one that says which names must carry an example, runs just
those (about 20 s here), and fails when an example is removed or is skipped without a reason
given here.
"""

from __future__ import annotations

import doctest
import inspect

import numpy as np
import pytest

import vibroscope

CURATED = sorted(n for n in vibroscope.__all__ if not n.startswith("__"))  # _LAZY, Signals, the errors

# Names whose examples are all marked ``# doctest: +SKIP``, with the reason.
SKIPPED = {
    "diagnose": "the candidate fits take 10-20 s; tests/gap/test_diagnose.py runs the same case",
}
# Names without an Examples section yet, with the reason (strict: adding one fails until removed).
WITHOUT: dict[str, str] = {}


def _examples(name: str) -> list[doctest.DocTest]:
    obj = getattr(vibroscope, name)
    finder = doctest.DocTestFinder(recurse=False)
    globs = dict(vars(inspect.getmodule(obj)))
    return [t for t in finder.find(obj, name, globs=globs) if t.examples]


def test_every_curated_name_is_collected():
    assert {"read_mcap", "frf", "ssi_cov", "fdd", "diagnose", "Signals", "VibroscopeError"} <= set(CURATED)
    assert set(vibroscope._LAZY) <= set(CURATED)
    assert set(SKIPPED) | set(WITHOUT) <= set(CURATED)


@pytest.mark.parametrize("name", CURATED)
def test_curated_name_has_a_passing_example(name):
    obj = getattr(vibroscope, name)
    has_section = "Examples\n--------" in (inspect.getdoc(obj) or "")
    if name in WITHOUT:
        assert not has_section, f"{name} has an Examples section now: remove it from WITHOUT"
        pytest.xfail(WITHOUT[name])
    assert has_section, f"{name} has no Examples section"
    tests = _examples(name)
    assert tests, f"{name}: the Examples section holds no doctest"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    with np.errstate(all="ignore"):
        for t in tests:
            runner.run(t)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{name}: {result.failed} example(s) failed (run pytest --doctest-modules)"
    skipped = sum(ex.options.get(doctest.SKIP, False) for t in tests for ex in t.examples)
    ran = sum(len(t.examples) for t in tests) - skipped
    if name in SKIPPED:
        assert skipped, f"{name} runs all its examples now: remove it from SKIPPED"
    else:
        assert ran >= 2 and not skipped, f"{name}: {skipped} example(s) skipped, {ran} run"
