"""Project-level checks: architecture boundaries, README/CI agreement, documented public API."""

from __future__ import annotations

import inspect
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_numerical_core_imports_no_edge_library():
    """GUIDE: importing the numerical core never imports rerun, mcap or dask."""
    code = (
        "import sys, vibroscope, vibroscope.spectral, vibroscope.modal, vibroscope.models;"
        "bad = [m for m in ('rerun', 'mcap', 'dask', 'matplotlib.pyplot') if m in sys.modules];"
        "print(','.join(bad))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


@pytest.mark.parametrize("room, allowed", [
    ("spectral", ("signals", "spectral", "errors")),
    ("models", ("signals", "models", "errors")),
    ("modal", ("signals", "spectral", "modal", "errors")),
])
def test_rooms_import_only_what_the_guide_allows(room, allowed):
    """Module-level imports only: a result's ``.plot()`` imports the viewers lazily, by design."""
    for f in (REPO / "vibroscope" / room).glob("*.py"):
        for m in re.findall(r"^(?:from|import) vibroscope\.(\w+)", f.read_text(), re.M):
            assert m in allowed, f"{room}/{f.name} imports vibroscope.{m}"


def test_ci_runs_the_readme_test_command():
    readme = (REPO / "README.md").read_text()
    ci = (REPO / ".ci" / "run").read_text()
    blocks = re.findall(r"```(?:bash|sh)\n(.*?)```", readme, re.S)
    cmds = [ln.strip() for b in blocks for ln in b.splitlines() if ln.strip() and not ln.startswith("#")]
    setup = [c for c in cmds if "venv" in c]
    assert len(setup) == 2, f"README must hold exactly two set-up commands, found {setup}"
    test_cmd = next(c for c in setup if "pytest" in c)
    assert test_cmd in ci


PUBLIC = [
    "vibroscope.spectral.welch",
    "vibroscope.spectral.csd_matrix",
    "vibroscope.spectral.frf",
    "vibroscope.spectral.coherence",
    "vibroscope.spectral.amplitude_spectrum",
    "vibroscope.spectral.spectrogram",
    "vibroscope.modal.fdd",
    "vibroscope.modal.peak_picking",
    "vibroscope.modal.mac",
    "vibroscope.modal.lscf",
    "vibroscope.modal.lsfd",
    "vibroscope.modal.ssi_cov",
    "vibroscope.modal.select_modes",
    "vibroscope.modal.auto_ssi",
    "vibroscope.modal.auto_lscf",
    "vibroscope.io.read_frf",
    "vibroscope.spectral.integration.integrate",
    "vibroscope.spectral.periodic.frf_periodic",
    "vibroscope.io.read_mcap",
    "vibroscope.io.write_ros2_mcap",
    "vibroscope.io.mcap_info",
    "vibroscope.models.simulate.simulate",
    "vibroscope.models.modelfile.load_model",
]


@pytest.mark.parametrize("qualname", PUBLIC)
def test_public_functions_document_every_parameter(qualname):
    """Like python-control's docstrings_test: every parameter of a public function is documented."""
    import importlib

    mod, name = qualname.rsplit(".", 1)
    fn = getattr(importlib.import_module(mod), name)
    doc = inspect.getdoc(fn) or ""
    assert "Parameters" in doc or not inspect.signature(fn).parameters, f"{qualname} has no Parameters section"
    for p in inspect.signature(fn).parameters.values():
        if p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL):
            continue
        assert re.search(rf"^\s*{p.name}\b|[ ,]{p.name}\b.*:", doc, re.M), f"{qualname}: parameter {p.name!r} undocumented"
