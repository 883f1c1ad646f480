"""Fuzzing the command line (hypothesis): random argument lists built from the real sub-commands
and their option names, with hostile values (empty strings, negative / NaN / huge numbers,
missing files, folders, unicode, existing data files).

Whatever the arguments, ``vibroscope.cli.main`` returns or exits with 0, 1, 2 or 130, prints no
traceback, reports an error in one line (argparse's usage errors: exit 2), leaves every input
file byte-identical and no temporary file behind. Bounded: ``MAX_EXAMPLES`` (60, derandomized) and
no deadline. Each crash it found is a regression test at the end of this file.

For a longer random exploration: ``VIBROSCOPE_FUZZ_EXAMPLES=400`` (random seed) and
``VIBROSCOPE_FUZZ_LOG=FILE`` (appends every case's argv, status and stderr tail).
"""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vibroscope.cli import build_parser, main

MAX_EXAMPLES = int(os.environ.get("VIBROSCOPE_FUZZ_EXAMPLES", 60))

#: never drawn: a viewer (network, a process), the traceback switch, help (tested elsewhere)
EXCLUDED = {"--spawn", "--connect", "--debug", "-h", "--help"}
#: options whose value is written (their values come from the output pool, never an input file)
OUTPUT_OPTIONS = {"--json", "--rrd", "--figures", "--out", "--export-model", "--uff55", "--uff15", "--uff58"}

NUMBERS = ["-1", "0", "nan", "inf", "-inf", "1e308", "1e400", "1e-300", "3", "0.5", "2.5", "-0", "١٢",
           "999999999999999999999", "", " ", "abc", "1,2", "auto", "Ω", "--", "-5", "0x10", "1_000"]
TEXT = ["", " ", "x", "/imu/m1.linear_acceleration.x", "/actuator/force.wrench.force.x", "/nope.a.b",
        "random:f_lo=1,f_hi=20,rms=1", "step:amplitude=1", "sweep:f0=-1,f1=nan", "impact:peak=1e400",
        "friction,backlash", "bogus", "Ω/ü.ß", "a" * 300, "0-1", "5-2", "\x00", "..", "-"]

MODEL = """\
kind = "lumped"
[[dof]]
name = "m1"
mass = 1.0
[[element]]
type = "spring"
between = ["m1", "ground"]
k = 1.0e4
[[input]]
channel = "/fuzz/in.wrench.force.x"
dof = "m1"
quantity = "force"
[[output]]
channel = "/fuzz/out.linear_acceleration.x"
dof = "m1"
quantity = "acceleration"
"""


def _commands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {name: p for name, p in sub.choices.items()}


COMMANDS = _commands()


@pytest.fixture(scope="module")
def pools(tmp_path_factory, shared_data_or_none):
    """Input files (a 2 s demo log, a model whose channels the log lacks, a sweep, hostile files),
    their bytes, and a folder for the outputs."""
    from vibroscope.commands.demo import make_demo_log

    d = tmp_path_factory.mktemp("fuzz")
    inputs = d / "in"
    inputs.mkdir()
    log = inputs / "tiny.mcap"
    make_demo_log(log, duration=2.0, fs=100.0)
    (inputs / "m.toml").write_text(MODEL)
    (inputs / "sweep.csv").write_text("A\n0.006\n0.007\n")
    (inputs / "empty.mcap").write_bytes(b"")
    (inputs / "garbage.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    (inputs / "not_mcap.rrd").write_bytes(b"RRF2" + b"\x00" * 64)
    (inputs / "ünï cödé ∂.mcap").write_bytes(log.read_bytes()[:3000])  # truncated, unicode name
    (inputs / "frf.csv").write_text("f,re,im\n1,2,3\nx,,\n")
    (inputs / "a_folder").mkdir()
    files = [p for p in inputs.iterdir() if p.is_file()]
    paths = [str(p) for p in files] + [str(inputs / "a_folder"), str(inputs / "missing.mcap"), "", ".", "/",
                                        "/dev/null"]
    if shared_data_or_none is not None:
        for rel in ("README.md", "lumo/coords_lumo.csv",
                    "mcap/conformance/OneMessage/OneMessage-ch-chx-mx-pad-rch-rsh-st-sum.mcap"):
            if (shared_data_or_none / rel).exists():
                paths.append(str(shared_data_or_none / rel))
    out = d / "out"
    out.mkdir()
    outputs = [str(out / n) for n in ("r.json", "r.rrd", "figs", "m.toml", "o.mcap", "ü ∂.uff", "sub/deep/x.json")]
    outputs += ["", str(inputs / "a_folder")] + [str(p) for p in files]  # inputs: must be refused
    return {"dir": d, "inputs": files, "bytes": {p: p.read_bytes() for p in files}, "paths": paths,
            "outputs": outputs, "out": out, "log": str(log), "model": str(inputs / "m.toml"),
            "csv": str(inputs / "frf.csv")}


@pytest.fixture(scope="module")
def shared_data_or_none():
    repo = Path(__file__).resolve().parents[1]
    data = Path(os.environ.get("VIBROSCOPE_SHARED_DATA", repo.parent / "shared" / "data"))
    return data if data.is_dir() else None


def _value(draw, action, pools):
    opt = action.option_strings[0] if action.option_strings else ""
    if action.choices is not None and draw(st.booleans()):
        return draw(st.sampled_from([str(c) for c in action.choices]))
    if opt in OUTPUT_OPTIONS:
        return draw(st.sampled_from(pools["outputs"]))
    if action.type in (float, int):
        return draw(st.sampled_from(NUMBERS))
    if action.type is Path or opt in ("--coords", "--input", "--sweep"):
        return draw(st.sampled_from(pools["paths"] + TEXT))
    if opt in ("--input", "--outputs") and draw(st.booleans()):
        return draw(st.sampled_from(["/actuator/force.wrench.force.x", "/imu/m1.linear_acceleration.x"]))
    return draw(st.sampled_from(TEXT + NUMBERS + pools["paths"]))


@st.composite
def argvs(draw, pools):
    name = draw(st.sampled_from(sorted(COMMANDS)))
    parser = COMMANDS[name]
    argv = [name]
    for action in parser._actions:  # positionals, each with a hostile value (or left out now and then)
        if action.option_strings or draw(st.integers(0, 9)) == 0:
            continue
        n = 1 if action.nargs in (None, 1) else draw(st.integers(1, 2))
        for _ in range(n):
            if name == "convert" and action.dest == "output":
                argv.append(draw(st.sampled_from(pools["outputs"][:7])))  # convert's own rule is C2's
            else:
                likely = {"model": [pools["model"], "pneumatic"] if name == "compare" else [pools["model"]],
                          "input": [pools["csv"]]}.get(action.dest, [pools["log"]])
                argv.append(draw(st.sampled_from(likely) | st.sampled_from(pools["paths"])))
    options = [a for a in parser._actions if a.option_strings and not EXCLUDED & set(a.option_strings)]
    for action in draw(st.lists(st.sampled_from(options), max_size=4)):
        opt = draw(st.sampled_from(action.option_strings))
        if action.nargs == 0:
            argv.append(opt)
        elif action.nargs == "+":
            argv += [opt] + [_value(draw, action, pools) for _ in range(draw(st.integers(1, 2)))]
        else:
            argv += [opt, _value(draw, action, pools)]
    # keep each case cheap: no long simulations, no figures or recordings of a successful analysis
    if name == "demo":
        argv += ["--duration", draw(st.sampled_from(["-1", "0", "nan", "1e400", "0.3", "x"])), "--out",
                 str(pools["out"] / "demo")]
    if name == "simulate":
        argv += ["--duration", draw(st.sampled_from(["-1", "0", "nan", "1e400", "0.2", "x"]))]
        if "--out" not in argv:
            argv += ["--out", draw(st.sampled_from(pools["outputs"]))]
        if "--excitation" not in argv and "--input" not in argv:
            argv += ["--excitation", draw(st.sampled_from(TEXT))]
    if name in ("analyse", "modal"):
        argv += ["--no-figures", "--no-rrd"]
    if name == "gap":
        argv += ["--no-progress"]
    return argv


def _run(argv) -> int:
    try:
        return main(argv)
    except SystemExit as exc:  # argparse: usage errors (2), --help (0)
        return 0 if exc.code is None else exc.code


_TQDM = re.compile(r"\d+%\||it/s|s/it")


def _check(argv, rc, out, err, pools):
    assert rc in (0, 1, 2, 130), (argv, rc, err)
    assert "Traceback" not in err and "Traceback" not in out, (argv, err)
    if rc == 2:
        assert "usage:" in err or "usage:" in out, (argv, err)
        return
    lines = [ln for ln in err.splitlines() if ln.strip() and not _TQDM.search(ln)
             and not ln.startswith(f"vibroscope {argv[0]}: warning: ")]
    if rc == 1:
        assert len(lines) == 1 and lines[0].startswith(f"vibroscope {argv[0]}: error: "), (argv, err)
    else:
        assert not lines, (argv, err)
    # every file given as an input (not as the value of an output option) is byte-identical; other
    # files of the pool may be written as outputs, and are restored for the next case
    inputs = {a for prev, a in zip([""] + argv, argv) if prev not in OUTPUT_OPTIONS}
    for p, data in pools["bytes"].items():
        now = p.read_bytes() if p.is_file() else None
        if str(p) in inputs:
            assert now == data, (argv, p)
        if now != data:
            p.write_bytes(data)
    assert not [p for p in pools["dir"].rglob("*") if ".tmp-" in p.name], argv  # no temporary left behind


COUNT = {"cases": 0}


@settings(max_examples=MAX_EXAMPLES, deadline=None, derandomize=not os.environ.get("VIBROSCOPE_FUZZ_EXAMPLES"),
          database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                 HealthCheck.data_too_large])
@given(data=st.data())
def test_cli_fuzz(data, pools, capsys):
    argv = data.draw(argvs(pools))
    capsys.readouterr()
    cwd = os.getcwd()
    os.chdir(pools["out"])
    try:
        rc = _run(argv)
    finally:
        os.chdir(cwd)
    out, err = capsys.readouterr()
    COUNT["cases"] += 1
    if os.environ.get("VIBROSCOPE_FUZZ_LOG"):
        with open(os.environ["VIBROSCOPE_FUZZ_LOG"], "a") as f:
            f.write(f"{rc} {argv!r}\n{err[-300:]}\n")
    _check(argv, rc, out, err, pools)


def test_fuzz_case_count():
    """The number of fuzz cases run (reported by ``-rA``); runs after :func:`test_cli_fuzz`."""
    if COUNT["cases"] == 0:
        pytest.skip("test_cli_fuzz not run in this session")
    assert COUNT["cases"] >= MAX_EXAMPLES // 2
    print(f"CLI fuzz cases run: {COUNT['cases']}")


# ---------------------------------------------------------------- regression tests (crashes the fuzz found)

def _one_error_line(argv, capsys, expect: str) -> None:
    capsys.readouterr()
    assert _run(argv) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"vibroscope {argv[0]}: error: ") and expect in err[0], err
    assert "ValueError" not in err[0] and "--debug" not in err[0], err  # a diagnosis, not a crash


@pytest.mark.parametrize("opts,expect", [
    (["--duration", "-1"], "--duration -1: must be a positive, finite number"),  # was ValueError n=-1000
    (["--fs", "-1", "--duration", "nan"], "--duration nan: must be a positive, finite number"),  # NaN to int
    (["--duration", "0.01"], "10 samples, the demo needs 64 to 1e8"),
    (["--duration", "1e300"], "the demo needs 64 to 1e8"),
])
def test_regression_demo_options(opts, expect, tmp_path, capsys):
    _one_error_line(["demo", *opts, "--out", str(tmp_path)], capsys, expect)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("command", ["gap", "simulate", "compare"])
def test_regression_binary_model_file(command, pools, capsys):
    """A binary file as the model escaped as ``UnicodeDecodeError``."""
    bad = str(pools["dir"] / "in" / "garbage.mcap")
    argv = {"gap": ["gap", bad, pools["log"]],
            "simulate": ["simulate", bad, "--excitation", "step:amplitude=1", "--out", str(pools["out"] / "s.mcap")],
            "compare": ["compare", bad, "--sweep", str(pools["dir"] / "in" / "sweep.csv"),
                        "--out", str(pools["out"])]}[command]
    _one_error_line(argv, capsys, "not a text (UTF-8) model file")


def test_regression_modal_uff55_without_modes(pools, capsys):
    """No mode identified + ``--uff55`` escaped as ``ValueError: the modal model has no modes``;
    and ``--out`` naming a file is refused before any work."""
    out = pools["out"] / "nomodes.uff"
    _one_error_line(["modal", pools["log"], "--uff55", str(out), "--no-figures", "--no-rrd"], capsys,
                    "--uff55: no mode was identified, nothing to write")
    assert not out.exists() and not [p for p in pools["out"].rglob("*") if ".tmp-" in p.name]
    _one_error_line(["modal", pools["log"], "--out", str(pools["dir"] / "in" / "empty.mcap")], capsys,
                    "is a file, not a folder")
    _one_error_line(["analyse", pools["log"], "--out", str(pools["dir"] / "in" / "empty.mcap")], capsys,
                    "is a file, not a folder")


@pytest.mark.parametrize("opts,expect", [
    (["--fs", "1e400"], "--fs inf: must be a positive, finite number"),  # was OverflowError
    (["--nperseg", "-1"], "--nperseg -1: must be a positive, finite number"),
    (["--ods", "1e308"], "--ods 1e+308: above the analysed band's top"),  # was ValueError
    (["--ods", "inf"], "--ods inf: frequencies must be positive and finite"),
])
def test_regression_analyse_options(opts, expect, pools, capsys, monkeypatch):
    monkeypatch.chdir(pools["out"])
    _one_error_line(["analyse", pools["log"], *opts, "--no-figures", "--no-rrd"], capsys, expect)


def test_regression_ods_without_modes(pools, capsys, monkeypatch):
    """``--ods`` when no mode was identified escaped as ``cannot reshape array of size 0``."""
    monkeypatch.chdir(pools["out"])
    capsys.readouterr()
    # output-only (the demo log's force would be the input): the ODS from the CSD, no mode passing
    assert _run(["analyse", pools["log"], "--output-only", "--ods", "2.5", "--no-figures", "--rrd", "ods.rrd"]) == 0
    out = capsys.readouterr().out
    assert "ODS at 3.125 Hz" in out and "no mode passed" in out  # the nearest line to 2.5 Hz (df 1.5625 Hz)
    from vibroscope.viewers.rerun_view import read_rrd

    assert any("/modes/" in e for e in read_rrd(pools["out"] / "ods.rrd"))


def test_regression_binary_sweep_file(pools, capsys):
    """A binary sweep CSV escaped as ``UnicodeDecodeError``."""
    _one_error_line(["compare", "pneumatic", "--sweep", str(pools["dir"] / "in" / "garbage.mcap"),
                     "--out", str(pools["out"])], capsys, "not a CSV sweep file (byte offset 0 is not UTF-8 text)")


@pytest.mark.parametrize("opts,expect", [
    (["--fs", "inf"], "--fs inf: must be a positive, finite number"),  # was OverflowError
    (["--duration", "1e400"], "--duration inf: must be a positive, finite number"),  # was OverflowError
    (["--noise", "nan"], "--noise nan: must be a finite number >= 0"),
    (["--fs", "1e308", "--duration", "1e10"], "samples; between 2 and 1e9 can be simulated"),
])
def test_regression_simulate_options(opts, expect, pools, capsys):
    out = pools["out"] / "sim.mcap"
    _one_error_line(["simulate", pools["model"], "--excitation", "step:amplitude=1", *opts, "--out", str(out)],
                    capsys, expect)
    assert not out.exists()
