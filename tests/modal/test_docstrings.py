"""Every public callable of vibroscope.modal documents each of its parameters (numpydoc), in the
spirit of python-control's ``docstrings_test``."""

from __future__ import annotations

import inspect
import re

import numpy as np
import pytest

import vibroscope.modal as modal


def _public_callables():
    for name in modal.__all__:
        obj = getattr(modal, name)
        if inspect.isclass(obj):
            for mname, meth in vars(obj).items():
                if not mname.startswith("_") and callable(meth) and not isinstance(meth, type):
                    yield f"{name}.{mname}", meth
        elif callable(obj):
            yield name, obj


@pytest.mark.parametrize("name,obj", list(_public_callables()), ids=lambda x: x if isinstance(x, str) else "")
def test_parameters_documented(name, obj):
    doc = inspect.getdoc(obj) or ""
    assert doc, f"{name} has no docstring"
    params = [p for p in inspect.signature(obj).parameters.values()
              if p.name not in ("self", "cls") and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    if not params:
        return
    documented = set()
    for line in doc.splitlines():
        m = re.match(r"^([A-Za-z_][\w, ]*?)\s*:", line)
        if m:
            documented |= {s.strip() for s in m.group(1).split(",")}
    missing = [p.name for p in params if p.name not in documented]
    assert not missing, f"{name}: undocumented parameters {missing}"


def test_modal_model_plot(tmp_path):
    """``ModalModel.plot`` delegates to the viewers' ``plot_mode_shapes`` (matplotlib, Agg)."""
    pytest.importorskip("matplotlib")
    figures = pytest.importorskip("vibroscope.viewers.figures")
    if not hasattr(figures, "plot_mode_shapes"):
        pytest.skip("viewers.figures.plot_mode_shapes not available")
    m = modal.ModalModel([2.0, 5.0], [0.01, 0.02], [[1, 0.5, 0.2], [-0.3, 1, 0.4]], ["a", "b", "c"], "fdd")
    fig = m.plot()
    assert fig is not None
    fig.savefig(tmp_path / "modes.png")
    assert (tmp_path / "modes.png").stat().st_size > 0
    assert np.isfinite(m.natural_frequencies).all()


@pytest.mark.parametrize("module", ["_results", "mac", "peak_picking", "fdd", "ssi"])
def test_doctests(module):
    """The Examples of vibroscope.modal run (the package is not in pytest's doctest paths)."""
    import doctest
    import importlib

    mod = importlib.import_module(f"vibroscope.modal.{module}")
    res = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert res.failed == 0
