"""The modal-method registry (:mod:`vibroscope.modal.methods`) and the FRF-kind table
(:mod:`vibroscope.spectral.kinds`) are the only lists of their vocabularies: the CLI's choices are
theirs, every entry point gives the one error of an unknown or misfitting method, every registered
method recovers the known modes of the 3-DOF demo model under its key and its result name, and no
module of the package keeps a literal list of either vocabulary."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vibroscope.modal.methods import METHOD_CHOICES, MODAL_METHODS, lookup_method, resolve_method
from vibroscope.spectral.kinds import FRF_KIND_TABLE, FRF_KINDS

PACKAGE = Path(__file__).resolve().parents[2] / "vibroscope"
FS, NPERSEG, NSEG = 256.0, 2048, 24


def _option(parser, command: str, option: str):
    sub = next(a for a in parser._actions if a.dest == "command")
    return next(a for a in sub.choices[command]._actions if option in a.option_strings)


@pytest.mark.parametrize("command", ["analyse", "modal"])
def test_cli_method_choices_are_the_registry(command):
    from vibroscope.cli import build_parser

    assert tuple(_option(build_parser(), command, "--method").choices) == METHOD_CHOICES
    assert METHOD_CHOICES == ("auto", *dict.fromkeys(n for m in MODAL_METHODS.values() for n in (m.key, m.name)))


def test_cli_kind_choices_are_the_table():
    from vibroscope.cli import build_parser

    assert tuple(_option(build_parser(), "modal", "--kind").choices) == FRF_KINDS == tuple(FRF_KIND_TABLE)


def test_the_parser_imports_no_numerical_room():
    """The choices are read when checked or shown: building the parsers of ``analyse`` and ``modal``
    imports no registry's room."""
    code = ("import sys, argparse; from vibroscope.commands import analyse, modal;"
            "sub = argparse.ArgumentParser().add_subparsers(); analyse.add_parser(sub); modal.add_parser(sub);"
            "print([m for m in ('vibroscope.modal', 'vibroscope.spectral', 'scipy') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_help_lists_every_registered_name(capsys):
    from vibroscope.cli import main

    with pytest.raises(SystemExit):
        main(["modal", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "modal identification: " + ", ".join(METHOD_CHOICES) + " (" in text
    assert "does not say: " + ", ".join(FRF_KINDS) + " (" in text


@pytest.fixture(scope="module")
def demo():
    """(true natural frequencies Hz, forced Signals [force, 3 accelerations], ambient Signals [3 accelerations])."""
    from vibroscope.models import Input, demo_model
    from vibroscope.models.simulate import simulate

    model = demo_model()
    rng = np.random.default_rng(3)
    forced = simulate(model, rng.standard_normal(NPERSEG * NSEG), FS, noise=0.01, seed=4)
    amb = model.replace(inputs=tuple(Input(dof=d.name, channel=f"/f/{d.name}") for d in model.dofs))
    sig = simulate(amb, rng.standard_normal((model.n_dofs, NPERSEG * NSEG)), FS, noise=0.01, seed=5)
    return np.asarray(model.modes().natural_frequencies), forced, sig.select(sig.channels[model.n_dofs:])


def _error(fn) -> str:
    with pytest.raises(ValueError) as info:
        fn()
    return str(info.value)


@pytest.mark.parametrize("command", ["analyse", "modal"])
def test_the_cli_refuses_an_unknown_method_naming_the_registry(command, tmp_path, capsys):
    from vibroscope.cli import main

    with pytest.raises(SystemExit) as info:
        main([command, str(tmp_path / "x.mcap"), "--method", "ssi-cov"])
    assert info.value.code == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "invalid choice: 'ssi-cov' (choose from " + ", ".join(map(repr, METHOD_CHOICES)) + ")" in err


def test_an_unknown_method_gives_one_error_from_every_entry_point(demo, tmp_path):
    from vibroscope.commands.modal import identify_frf
    from vibroscope.pipeline import analyse_signals
    from vibroscope.spectral import csd_matrix, frf
    from vibroscope.stream import analyse_stream

    truth, forced, _ = demo
    want = _error(lambda: lookup_method("ssi-cov"))
    assert want.startswith("Invalid value for the 'method' parameter.") and "'ssi-cov'" in want
    assert all(repr(n) in want for n in METHOD_CHOICES)
    h = frf(csd_matrix(forced, nperseg=NPERSEG), forced.channels[0], forced.channels[1:])
    missing = tmp_path / "never-read.mcap"  # the method is checked before the log is opened
    assert _error(lambda: analyse_signals(forced, input=forced.channels[0], method="ssi-cov")) == want
    assert _error(lambda: analyse_stream(missing, method="ssi-cov")) == want
    assert _error(lambda: identify_frf(h, method="ssi-cov")) == want
    try:
        from vibroscope.fleet import analyse_fleet
    except ImportError:  # pragma: no cover - the [dask] extra
        return
    assert _error(lambda: analyse_fleet([str(missing)], method="ssi-cov")) == want


def test_a_misfit_gives_one_error_from_every_entry_point(demo, tmp_path):
    from vibroscope.commands.modal import identify_frf
    from vibroscope.pipeline import analyse_signals
    from vibroscope.spectral import csd_matrix, frf
    from vibroscope.stream import analyse_stream

    _, forced, amb = demo
    inp = forced.channels[0]
    missing = tmp_path / "never-read.mcap"
    h = frf(csd_matrix(forced, nperseg=NPERSEG), inp, forced.channels[1:])
    # an output-only method with an input: the same words from the pipeline, the stream and an FRF file
    out_only = "method='fdd' (FDD) is output-only; with an input use 'lscf', 'peak'"
    assert _error(lambda: resolve_method("fdd", has_input=True)) == out_only
    assert _error(lambda: analyse_signals(forced, input=inp, method="fdd")) == out_only
    assert _error(lambda: analyse_stream(missing, input=inp, method="fdd")) == out_only
    assert _error(lambda: identify_frf(h, method="fdd")) == out_only
    # an input-output method without an input; the stream, spectra only, offers fewer methods
    assert _error(lambda: analyse_signals(amb, method="peak")) == (
        "method='peak' (peak picking) needs an input (force) channel; output-only use 'ssi', 'polymax', 'fdd', 'efdd'")
    assert _error(lambda: analyse_stream(missing, method="peak")) == (
        "method='peak' (peak picking) needs an input (force) channel; output-only use 'fdd', 'efdd'")
    # the time series: the stream holds spectra only, whichever name is given
    for name in ("ssi", "ssi_cov", "polymax_oma"):
        assert "needs the time series" in _error(lambda: analyse_stream(missing, method=name))


@pytest.mark.parametrize("name", [n for n in METHOD_CHOICES if n != "auto"])
def test_every_registered_name_recovers_the_demo_modes(demo, name):
    """Each key and result name of the registry runs its method on the data it needs and finds the
    demo's three modes (18.4, 41.9, 60.4 Hz) within 1.5 %; the result carries the method's name."""
    from vibroscope.pipeline import analyse_signals

    truth, forced, amb = demo
    m = lookup_method(name)
    if m.needs_input:
        an = analyse_signals(forced, input=forced.channels[0], method=name, nperseg=NPERSEG)
    else:
        an = analyse_signals(amb, method=name, nperseg=NPERSEG, fmin=5.0, fmax=100.0)
    assert an.modal.method == m.name and an.settings["method"] == m.name
    f = np.asarray(an.modal.natural_frequencies)
    assert len(f) == 3, (name, f)
    np.testing.assert_allclose(np.sort(f), np.sort(truth), rtol=0.015)


def test_auto_and_polymax_with_an_input_are_lscf():
    assert resolve_method("auto", has_input=True).name == "lscf"
    assert resolve_method("polymax", has_input=True).name == "lscf"
    assert resolve_method("auto", has_input=False).name == "ssi_cov"
    assert resolve_method("auto", has_input=False, time_series=False).name == "efdd"


def _literals(tree):
    for n in ast.walk(tree):
        if isinstance(n, (ast.Tuple, ast.List, ast.Set, ast.Dict)):
            elts = [*n.keys, *n.values] if isinstance(n, ast.Dict) else n.elts
            yield n, {e.value for e in elts if isinstance(e, ast.Constant) and isinstance(e.value, str)}


REGISTRIES = ("modal/methods.py", "spectral/kinds.py")


def test_no_module_keeps_its_own_list():
    """No literal tuple, list, set or dict outside the registries names two methods or two FRF
    kinds (the packages' ``__init__`` list function names, some of which are method names)."""
    methods = {n for m in MODAL_METHODS.values() for n in (m.key, m.name)}
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "__init__.py" or path.relative_to(PACKAGE).as_posix() in REGISTRIES:
            continue
        for node, strings in _literals(ast.parse(path.read_text())):
            for vocab in (methods, set(FRF_KINDS)):
                if len(strings & vocab) >= 2:
                    found.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {sorted(strings & vocab)}")
    assert not found, found
