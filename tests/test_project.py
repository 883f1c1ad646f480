"""Project-level checks: architecture boundaries, README/CI agreement, documented public API."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
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
    ("spectral", ("signals", "spectral", "errors", "_checks")),
    ("models", ("signals", "models", "errors", "_checks", "_lazy")),
    ("modal", ("signals", "spectral", "modal", "errors", "_checks")),
    ("instruments", ("signals", "models", "instruments", "errors", "_checks")),
])
def test_rooms_import_only_what_the_guide_allows(room, allowed):
    """Module-level imports (the import-linter contracts below also see those inside functions)."""
    for f in (REPO / "vibroscope" / room).glob("*.py"):
        for m in re.findall(r"^(?:from|import) vibroscope\.(\w+)", f.read_text(), re.M):
            assert m in allowed, f"{room}/{f.name} imports vibroscope.{m}"


def test_import_linter_contracts_hold():
    """pyproject.toml's import-linter contracts (layers, independent commands, no circles) hold, imports
    inside functions included: ``lint-imports`` exits 0 (this is how CI runs it)."""
    pytest.importorskip("importlinter", reason="import-linter is not installed (it comes with the [dev] extra)")
    code = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", code, "--no-cache"], capture_output=True, text=True, cwd=REPO,
                         env=env)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
    assert "0 broken" in out.stdout


def test_results_name_only_figures_the_plotting_backend_offers():
    """Every ``draw("NAME", ...)`` in the package names a callable of the default backend, and no
    computing room imports ``vibroscope.viewers`` at all (inside functions included)."""
    import vibroscope.viewers as backend

    names = set()
    for f in (REPO / "vibroscope").rglob("*.py"):
        src = f.read_text()
        names |= set(re.findall(r'\bdraw\("(\w+)"', src))
        if f.parent.name in ("spectral", "modal", "gap", "instruments", "models", "io"):
            assert not re.search(r"^\s*(?:from|import) vibroscope\.viewers", src, re.M), f
    assert len(names) >= 12, sorted(names)
    for name in sorted(names):
        assert callable(getattr(backend, name)), name


def test_plotting_backend_is_chosen_by_name(monkeypatch):
    """set_backend() sends a result's .plot() to another module; a figure the backend lacks is an
    AttributeError naming the backend and the figure; an unimportable backend fails when chosen."""
    import types

    from vibroscope import _plotting
    from vibroscope.spectral import welch

    calls = []
    fake = types.ModuleType("fake_vibro_backend")
    fake.plot_spectrum = lambda result, **kw: calls.append((type(result).__name__, kw)) or "drawn"
    monkeypatch.setitem(sys.modules, "fake_vibro_backend", fake)
    spec = welch(np.random.default_rng(0).standard_normal(1024), fs=100.0, nperseg=128)
    try:
        _plotting.set_backend("fake_vibro_backend")
        assert spec.plot(db=True) == "drawn"
        assert calls == [("Spectrum", {"ax": None, "db": True, "channels": None})]
        with pytest.raises(AttributeError, match="fake_vibro_backend.*plot_frf"):
            _plotting.draw("plot_frf", spec)
    finally:
        _plotting.set_backend(None)
    assert _plotting.get_backend().__name__ == _plotting.DEFAULT_BACKEND
    with pytest.raises(ModuleNotFoundError):
        _plotting.set_backend("no_such_backend_module_xyz")
    assert _plotting.get_backend().__name__ == _plotting.DEFAULT_BACKEND


def test_import_graph_sees_imports_inside_functions():
    """The contracts would be blind without this: grimp records an import made inside a function
    (``commands/demo.py`` imports ``commands._read_log`` in its ``run``)."""
    grimp = pytest.importorskip("grimp", reason="import-linter is not installed (it comes with the [dev] extra)")
    graph = grimp.build_graph("vibroscope", cache_dir=None)
    lines = [d["line_contents"] for d in graph.get_import_details(importer="vibroscope.commands.demo",
                                                                   imported="vibroscope.commands._read_log")]
    assert lines and all(ln.startswith("from vibroscope.commands._read_log import") for ln in lines)
    src = (REPO / "vibroscope" / "commands" / "demo.py").read_text()
    assert not re.search(r"^from vibroscope\.commands\._read_log", src, re.M)  # not at module level


@pytest.mark.parametrize("package, name, module", [
    ("vibroscope", "welch", "vibroscope.spectral"), ("vibroscope.io", "read_frf", "vibroscope.io.frf_files"),
    ("vibroscope.viewers", "plot_frf", "vibroscope.viewers.figures"),
    ("vibroscope.gap", "diagnose", "vibroscope.gap.diagnosis"),
    ("vibroscope.models", "load_model", "vibroscope.models.modelfile"),
])
def test_packages_load_names_lazily_through_one_helper(package, name, module):
    """The package ``__init__`` modules share one lazy-import helper (vibroscope._lazy): the name is the
    defining module's object, listed by ``dir``, and an unknown name is an AttributeError naming the package."""
    import importlib

    from vibroscope._lazy import lazy_attributes

    pkg = importlib.import_module(package)
    assert pkg.__getattr__.__qualname__ == lazy_attributes.__qualname__ + ".<locals>.__getattr__"
    assert getattr(pkg, name) is getattr(importlib.import_module(module), name)
    assert name in dir(pkg)
    with pytest.raises(AttributeError, match=f"module '{package}' has no attribute 'nope'"):
        getattr(pkg, "nope")


def test_models_offers_every_public_name_of_its_lazy_modules():
    """``vibroscope.models`` reaches each public name of simulation, excitations, model files and the
    Bouc-Wen benchmark as the defining module's object (its lazy table is written out, so a name added
    to one of their ``__all__`` fails here until it is listed); ``simulate`` stays the submodule."""
    import importlib
    import types

    import vibroscope.models as models

    assert isinstance(models.simulate, types.ModuleType)
    for mod in ("simulate", "excitation", "modelfile", "boucwen_benchmark"):
        m = importlib.import_module(f"vibroscope.models.{mod}")
        for name in set(m.__all__) - {"simulate"}:
            assert getattr(models, name) is getattr(m, name), f"vibroscope.models.{name} (from {mod})"
            assert name in dir(models)


# private names imported from another module (issue 22 paid this debt: none left). A new one fails the
# test below, and so does an entry no longer imported.
KNOWN_PRIVATE_IMPORTS: set[tuple[str, str, str]] = set()


def test_no_new_private_name_is_imported_from_another_module():
    """GUIDE: a private name (``_x``) is never imported from another module -- it is made public where
    it is shared. Private submodules (``vibroscope.io._scan``) are modules, not names, and may be."""
    import ast

    found = set()
    for f in sorted((REPO / "vibroscope").rglob("*.py")):
        mod = ".".join(f.relative_to(REPO).with_suffix("").parts).removesuffix(".__init__")
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("vibroscope"):
                for a in node.names:
                    where = REPO.joinpath(*node.module.split("."), a.name)
                    if (a.name.startswith("_") and not a.name.startswith("__")
                            and not (where.with_suffix(".py").exists() or where.is_dir())):
                        found.add((mod, node.module, a.name))
    new = sorted(found - KNOWN_PRIVATE_IMPORTS)
    assert not new, f"private names imported from another module (make them public where shared): {new}"
    gone = sorted(KNOWN_PRIVATE_IMPORTS - found)
    assert not gone, f"no longer imported, remove from KNOWN_PRIVATE_IMPORTS (the list stays exact): {gone}"


def test_models_never_import_instruments():
    """GUIDE: instruments may use models, not the other way round (not even lazily)."""
    for f in (REPO / "vibroscope" / "models").glob("*.py"):
        assert not re.search(r"(?:from|import) vibroscope\.instruments", f.read_text()), f"models/{f.name}"


def test_ci_runs_the_readme_test_command():
    readme = (REPO / "README.md").read_text()
    ci = (REPO / ".ci" / "run").read_text()
    blocks = re.findall(r"```(?:bash|sh)\n(.*?)```", readme, re.S)
    cmds = [ln.strip() for b in blocks for ln in b.splitlines() if ln.strip() and not ln.startswith("#")]
    setup = [c for c in cmds if "venv" in c]
    assert len(setup) == 2, f"README must hold exactly two set-up commands, found {setup}"
    test_cmd = next(c for c in setup if "pytest" in c)
    assert test_cmd in ci


# Every parameter of every public function and class is documented: tests/test_docstrings.py.

LIGHT = ("rerun", "matplotlib", "mcap", "dask", "control", "numba")


def test_import_vibroscope_is_light_and_offers_the_first_names():
    """``import vibroscope`` loads none of the heavy edges; its curated names load on first use."""
    import vibroscope

    code = (
        "import sys, vibroscope;"
        f"heavy = [m for m in {LIGHT!r} if m in sys.modules];"
        "print(','.join(heavy));"
        "import inspect;"
        "names = [n for n in vibroscope.__all__ if not n.startswith('__')];"
        "bad = [n for n in names if not (inspect.isfunction(getattr(vibroscope, n)) or inspect.isclass(getattr(vibroscope, n)))];"
        "print(','.join(bad));"
        "print(','.join(sorted(set(dir(vibroscope)) & set(names))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    heavy, bad, listed = out.stdout.splitlines()
    assert heavy == "", f"import vibroscope imported {heavy}"
    assert bad == "", f"not a function or class: {bad}"
    assert set(listed.split(",")) == {n for n in vibroscope.__all__ if not n.startswith("__")}
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        vibroscope.nope  # noqa: B018


@pytest.mark.parametrize("name, module", [
    ("read_mcap", "vibroscope.io"), ("welch", "vibroscope.spectral"), ("csd_matrix", "vibroscope.spectral"),
    ("frf", "vibroscope.spectral"), ("lscf", "vibroscope.modal"), ("lsfd", "vibroscope.modal"),
    ("ssi_cov", "vibroscope.modal"), ("fdd", "vibroscope.modal"), ("peak_picking", "vibroscope.modal"),
    ("auto_ssi", "vibroscope.modal"), ("auto_lscf", "vibroscope.modal"),
    ("load_model", "vibroscope.models.modelfile"), ("simulate", "vibroscope.models.simulate"),
    ("diagnose", "vibroscope.gap"), ("Signals", "vibroscope.signals"),
])
def test_top_level_name_is_the_rooms_object(name, module):
    """Each curated name is the very object its room exports (not a copy, not a module)."""
    import importlib

    import vibroscope

    assert getattr(vibroscope, name) is getattr(importlib.import_module(module), name)
    assert name in vibroscope.__all__


def _readme_command(needle: str) -> list[str]:
    import shlex

    readme = (REPO / "README.md").read_text()
    lines = [ln.strip(" -`") for ln in readme.splitlines() if needle in ln and "vibroscope simulate" in ln]
    assert lines, f"README names no `vibroscope simulate {needle}` command"
    cmd = lines[0][lines[0].index("vibroscope simulate"):]
    return shlex.split(cmd[: cmd.index("`")] if "`" in cmd else cmd)


def test_example_model_file_simulates(tmp_path, monkeypatch):
    """examples/models/three_dof.toml is the demo model, and the README's command simulates it
    into a log that reads back as the model's simulation."""
    import numpy as np

    from vibroscope.cli import main
    from vibroscope.io import read_mcap
    from vibroscope.models import demo_model
    from vibroscope.models.modelfile import load_model
    from vibroscope.models.simulate import simulate

    path = REPO / "examples" / "models" / "three_dof.toml"
    model = load_model(path)
    assert model == demo_model()
    argv = _readme_command("examples/models/three_dof.toml")
    assert argv[:3] == ["vibroscope", "simulate", "examples/models/three_dof.toml"] and "--excitation" in argv
    out = tmp_path / "three_dof.mcap"
    argv[argv.index("--out") + 1] = str(out)
    monkeypatch.chdir(REPO)
    assert main([*argv[1:], "--duration", "20", "--seed", "1"]) == 0
    chans = model.input_channels() + model.output_channels()
    log = read_mcap(out, channels=chans)
    assert log.channels == tuple(chans) and log.fs == pytest.approx(1000.0) and log.n_samples == 20_000
    assert np.std(log.data[0]) == pytest.approx(10.0, rel=0.05)  # rms=10 of the excitation
    ref = simulate(model, log.data[0], log.fs)
    np.testing.assert_allclose(log.data[1:], ref.data[1:], rtol=0, atol=1e-9 * np.abs(ref.data[1:]).max())


def test_cli_help_and_info_load_no_heavy_edge(tmp_path):
    """`vibroscope --help` and `vibroscope info LOG` start without rerun, matplotlib, control, dask or numba
    (issue #9, start-up): only what the command uses is imported."""
    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    log = tmp_path / "x.mcap"
    write_ros2_mcap(log, Signals(data=np.zeros((1, 100)) + 1.0, fs=100.0, channels=["/imu.linear_acceleration.x"],
                                 units=["m/s^2"]))
    heavy = ("rerun", "matplotlib", "control", "dask", "numba")
    for argv in (["--help"], ["info", str(log)]):
        code = (
            "import sys, contextlib, io\n"
            "from vibroscope.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n"
            f"        main({argv!r})\n"
            "    except SystemExit:\n"
            "        pass\n"
            f"print(','.join(m for m in {heavy!r} if m in sys.modules))\n"
        )
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
        assert out.stdout.strip() == "", f"vibroscope {' '.join(argv)} imported {out.stdout.strip()}"


def test_dataclasses_of_more_than_five_fields_are_built_by_name():
    """House rule (CONTRIBUTING.md, Names): a dataclass of more than five fields is
    ``kw_only=True``, so no call can pass its fields in the wrong order. Checked on the source
    (every ``@dataclass`` class of the package with more than five annotated fields)."""
    import ast

    offenders = []
    for path in sorted((REPO / "vibroscope").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if not isinstance(node, ast.ClassDef):
                continue
            decs = [d for d in node.decorator_list if "dataclass" in ast.unparse(d)]
            if not decs:
                continue
            n_fields = sum(1 for b in node.body if isinstance(b, ast.AnnAssign) and "ClassVar" not in ast.unparse(b.annotation))
            if n_fields > 5 and "kw_only=True" not in ast.unparse(decs[0]):
                offenders.append(f"{path.relative_to(REPO)}:{node.lineno} {node.name} ({n_fields} fields)")
    assert not offenders, "dataclasses of more than five fields without kw_only=True:\n" + "\n".join(offenders)
