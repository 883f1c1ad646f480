"""Outputs of the commands: named after the input and the command, in the current directory or
``--out``; written atomically (an interrupted run leaves earlier outputs byte-identical and no
temporaries); never written over an input."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from vibroscope.cli import main
from vibroscope.commands._outputs import TEMP_MARK, AtomicOutputs, check_outputs, default_output
from vibroscope.errors import VibroscopeError
from vibroscope.provenance import json_report

#: an earlier recording as vibroscope writes them (rerun's magic, the application id in the store info)
EARLIER_RRD = b"RRF2 application vibroscope: an earlier complete recording"


def _ours_json(text: str) -> str:
    """A JSON report as vibroscope writes it (its first key the generator), holding `text`."""
    import json

    return json.dumps(json_report({"text": text}))


def _ours_png(text: bytes) -> bytes:
    """PNG bytes as vibroscope's figures start (the ``Software`` text before the image), then `text`."""
    data = b"Software\0vibroscope test"
    return b"\x89PNG\r\n\x1a\n" + len(data).to_bytes(4, "big") + b"tEXt" + data + b"\0\0\0\0" + text

REPO = Path(__file__).resolve().parents[1]
FORCE = "/actuator/force.wrench.force.x"

MODEL = """\
kind = "lumped"
[[dof]]
name = "m1"
mass = 1.0
[[element]]
type = "spring"
between = ["m1", "ground"]
k = 1.0e4
[[element]]
type = "damper"
between = ["m1", "ground"]
c = 5.0
[[input]]
channel = "/actuator/force.wrench.force.x"
dof = "m1"
quantity = "force"
[[output]]
channel = "/imu/m1.linear_acceleration.x"
dof = "m1"
quantity = "acceleration"
"""


@pytest.fixture(scope="module")
def tiny_log(tmp_path_factory):
    """A 4 s, 200 Hz demo log (force + 3 Imu), written once; tests must not change it."""
    from vibroscope.commands.demo import make_demo_log

    path = tmp_path_factory.mktemp("tiny") / "tiny.mcap"
    make_demo_log(path, duration=4.0, fs=200.0)
    return path


def _temps(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if TEMP_MARK in p.name]


def _err_lines(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]


# ---------------------------------------------------------------- the building blocks

def test_default_output_names_after_the_source_and_command(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert default_output("/data/ro/run1.mcap", "analyse", ".rrd") == tmp_path / "run1_analyse.rrd"
    assert default_output("x/run1.mcap", "modal", "_figures", "out") == Path("out") / "run1_modal_figures"


def test_check_outputs_refuses_an_input_by_any_spelling(tmp_path, monkeypatch):
    log = tmp_path / "a.mcap"
    log.write_bytes(b"x")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    for spelling in (log, Path("a.mcap"), Path("sub/../a.mcap")):
        with pytest.raises(VibroscopeError, match=r"--json .* is the input log .*a\.mcap: an output never"):
            check_outputs({"--json": spelling}, {"log": log})
    os.link(log, tmp_path / "hard.mcap")  # the same file under another name
    with pytest.raises(VibroscopeError, match="--rrd"):
        check_outputs({"--rrd": tmp_path / "hard.mcap"}, {"log": [tmp_path / "b", log]})
    check_outputs({"--json": tmp_path / "b.json", "--rrd": None}, {"log": log, "coords": None})


def test_atomic_outputs_commit_replace_and_discard(tmp_path, capsys):
    old = tmp_path / "r.json"
    old.write_text(_ours_json("earlier"))
    with AtomicOutputs() as tx:
        t = tx.file(old)
        assert t.parent == tmp_path and t.name.startswith(".r") and TEMP_MARK in t.name and t.suffix == ".json"
        t.write_text(_ours_json("new"))
        assert old.read_text() == _ours_json("earlier")  # nothing moves before the end
        d = tx.directory(tmp_path / "figs")
        (d / "a.png").write_bytes(b"png")
        assert tx.final(d / "a.png") == tmp_path / "figs" / "a.png"
    assert old.read_text() == _ours_json("new") and (tmp_path / "figs" / "a.png").read_bytes() == b"png"
    assert capsys.readouterr().out == f"replacing {old} (earlier output)\n"
    assert not _temps(tmp_path)
    with pytest.raises(KeyboardInterrupt):
        with AtomicOutputs() as tx:
            tx.file(old).write_text("partial")
            (tx.directory(tmp_path / "figs") / "b.png").write_bytes(b"partial")
            raise KeyboardInterrupt
    assert old.read_text() == _ours_json("new") and sorted(p.name for p in (tmp_path / "figs").iterdir()) == ["a.png"]
    assert not _temps(tmp_path)


def test_figures_folder_swapped_whole_or_merged_when_it_holds_other_files(tmp_path, capsys):
    figs = tmp_path / "figs"
    figs.mkdir()
    (figs / "stale.png").write_bytes(_ours_png(b"old run"))
    with AtomicOutputs() as tx:
        (tx.directory(figs) / "new.png").write_bytes(b"new")
    assert sorted(p.name for p in figs.iterdir()) == ["new.png"]  # an earlier run's figures: replaced whole
    # a folder with other files (e.g. the current directory): only the figures move in, nothing is removed
    (tmp_path / "notes.txt").write_text("keep")
    log = tmp_path / "in.png"
    log.write_bytes(b"input")
    with AtomicOutputs(inputs=[log]) as tx:
        (tx.directory(tmp_path) / "psd.png").write_bytes(b"psd")
    assert (tmp_path / "notes.txt").read_text() == "keep" and (tmp_path / "psd.png").read_bytes() == b"psd"
    assert log.read_bytes() == b"input"
    with pytest.raises(VibroscopeError, match="never overwrites an input"):
        with AtomicOutputs(inputs=[log]) as tx:
            (tx.directory(tmp_path) / "in.png").write_bytes(b"figure")
    assert log.read_bytes() == b"input" and not _temps(tmp_path)


def test_ctrl_c_right_after_the_temporary_folder_is_made_leaves_no_temporary(tmp_path, monkeypatch):
    """The race CI met once under load: SIGINT between ``mkdir`` of the figures temporary and its
    being listed for removal left ``.NAME.tmp-PID`` behind."""
    real_mkdir = Path.mkdir

    def mkdir_then_ctrl_c(self, *a, **k):
        real_mkdir(self, *a, **k)
        if TEMP_MARK in self.name:
            raise KeyboardInterrupt

    monkeypatch.setattr(Path, "mkdir", mkdir_then_ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        with AtomicOutputs() as tx:
            tx.directory(tmp_path / "figs")
    assert not _temps(tmp_path) and not (tmp_path / "figs").exists()


# ---------------------------------------------------------------- where the outputs go

def test_analyse_writes_in_the_current_directory_named_after_log_and_command(tiny_log, tmp_path, monkeypatch,
                                                                            capsys):
    monkeypatch.chdir(tmp_path)
    before = sorted(p.name for p in tiny_log.parent.iterdir())
    assert main(["analyse", str(tiny_log)]) == 0
    rrd, figs = tmp_path / "tiny_analyse.rrd", tmp_path / "tiny_analyse_figures"
    assert rrd.stat().st_size > 10_000 and (figs / "psd.png").is_file()
    assert sorted(p.name for p in tiny_log.parent.iterdir()) == before  # nothing beside the log
    out = capsys.readouterr().out
    assert "replacing" not in out
    first = rrd.read_bytes()
    # a second run says what it replaces, one line per output
    assert main(["analyse", str(tiny_log), "--out", str(tmp_path), "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert f"replacing {rrd} (earlier output)" in out and "replacing" not in out.replace(f"replacing {rrd}", "")
    from vibroscope.viewers.rerun_view import read_rrd

    assert read_rrd(rrd) and len(rrd.read_bytes()) > len(first) // 2
    assert not _temps(tmp_path)
    # --out DIR: the folder is created; explicit --json still goes where it is told
    js = tmp_path / "elsewhere" / "s.json"
    assert main(["analyse", str(tiny_log), "--out", str(tmp_path / "o"), "--no-figures", "--json", str(js)]) == 0
    assert (tmp_path / "o" / "tiny_analyse.rrd").is_file() and js.is_file()
    assert not (tmp_path / "o" / "tiny_analyse_figures").exists()


def test_analyse_of_a_read_only_data_folder(shared_data, tmp_path, monkeypatch):
    """/work/shared/data is read-only: the outputs go to the current directory."""
    log = shared_data / "mcap" / "capstan" / "uncontrolled_data_0.mcap"
    if not log.is_file():
        pytest.skip(f"{log} not found")
    monkeypatch.chdir(tmp_path)
    mtime = log.stat().st_mtime_ns
    assert main(["analyse", str(log), "--no-figures"]) == 0
    assert (tmp_path / "uncontrolled_data_0_analyse.rrd").stat().st_size > 1000
    assert log.stat().st_mtime_ns == mtime
    assert not [p for p in log.parent.iterdir() if "_analyse" in p.name or TEMP_MARK in p.name]


# ---------------------------------------------------------------- interrupted runs

def test_interrupt_while_writing_figures_keeps_the_earlier_recording(tiny_log, tmp_path, monkeypatch, capsys):
    import vibroscope.viewers.figures as figures

    monkeypatch.chdir(tmp_path)
    assert main(["analyse", str(tiny_log), "--json", "s.json"]) == 0
    rrd, js = tmp_path / "tiny_analyse.rrd", tmp_path / "s.json"
    earlier = rrd.read_bytes(), js.read_bytes()
    pngs = {p.name: p.read_bytes() for p in (tmp_path / "tiny_analyse_figures").iterdir()}
    capsys.readouterr()

    def interrupted(out_dir, **kw):
        (Path(out_dir) / "signals.png").write_bytes(b"half a PNG")  # Ctrl-C while the figures are drawn
        raise KeyboardInterrupt

    monkeypatch.setattr(figures, "figure_jobs", interrupted)
    assert main(["analyse", str(tiny_log), "--json", "s.json"]) == 130
    assert _err_lines(capsys) == ["vibroscope analyse: interrupted"]
    assert (rrd.read_bytes(), js.read_bytes()) == earlier
    assert {p.name: p.read_bytes() for p in (tmp_path / "tiny_analyse_figures").iterdir()} == pngs
    assert not _temps(tmp_path)


def test_interrupt_while_writing_the_recording_leaves_no_partial_rrd(tiny_log, tmp_path, monkeypatch, capsys):
    import vibroscope.viewers.rerun_view as rv

    monkeypatch.chdir(tmp_path)
    rrd = tmp_path / "tiny_analyse.rrd"
    rrd.write_bytes(EARLIER_RRD)
    seen = []

    def interrupted(**kw):
        Path(kw["rrd_path"]).write_bytes(b"RRF2 truncated")  # half a recording, then Ctrl-C
        seen.append(kw["rrd_path"])
        raise KeyboardInterrupt

    monkeypatch.setattr(rv, "log_analysis", interrupted)
    assert main(["analyse", str(tiny_log), "--no-figures"]) == 130
    assert seen and Path(seen[0]) != rrd and Path(seen[0]).parent == tmp_path
    assert rrd.read_bytes() == EARLIER_RRD
    assert not _temps(tmp_path)


def test_sigint_during_analyse_leaves_nothing_that_looks_complete(tiny_log, tmp_path):
    """A real Ctrl-C (SIGINT) to ``python -m vibroscope.cli analyse`` once it writes its temporaries."""
    earlier = tmp_path / "tiny_analyse.rrd"
    earlier.write_bytes(EARLIER_RRD)
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen([sys.executable, "-m", "vibroscope.cli", "analyse", str(tiny_log)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.monotonic() + 60
    while proc.poll() is None and not _temps(tmp_path) and time.monotonic() < deadline:
        time.sleep(0.005)
    if proc.poll() is not None or not _temps(tmp_path):
        proc.kill()
        proc.communicate()
        pytest.skip("the run ended before its outputs were being written: timing unreliable here")
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    if proc.returncode == 0:
        pytest.skip("SIGINT arrived after the outputs were complete: timing unreliable here")
    assert proc.returncode == 130, err
    assert "vibroscope analyse: interrupted" in err and "Traceback" not in err
    assert earlier.read_bytes() == EARLIER_RRD
    assert not (tmp_path / "tiny_analyse_figures").exists()
    assert not _temps(tmp_path)


# ---------------------------------------------------------------- an output never overwrites an input

@pytest.fixture
def inputs(tiny_log, tmp_path):
    """Copies of the tiny log, a model file, a sweep CSV and a coordinates file, with their bytes."""
    log = tmp_path / "in.mcap"
    log.write_bytes(tiny_log.read_bytes())
    model = tmp_path / "m.toml"
    model.write_text(MODEL)
    sweep = tmp_path / "sweep.csv"
    sweep.write_text("A\n0.006\n0.007\n")
    return {"log": log, "model": model, "sweep": sweep}


@pytest.mark.parametrize("argv,victim", [
    (["analyse", "{log}", "--json", "{log}"], "log"),
    (["analyse", "{log}", "--rrd", "{log}"], "log"),
    (["analyse", "{log}", "--figures", "{log}"], "log"),
    (["analyse", "{log}", "--coords", "{sweep}", "--json", "{sweep}"], "sweep"),
    (["modal", "{log}", "--json", "{log}"], "log"),
    (["modal", "{log}", "--rrd", "{log}"], "log"),
    (["modal", "{log}", "--export-model", "{log}"], "log"),
    (["simulate", "{model}", "--excitation", "step:amplitude=1", "--out", "{model}"], "model"),
    (["simulate", "{model}", "--input", "{log}", "--out", "{log}"], "log"),
    (["compare", "pneumatic", "--sweep", "{sweep}", "--rrd", "{sweep}"], "sweep"),
    (["compare", "{model}", "--sweep", "{sweep}", "--rrd", "{model}"], "model"),
    (["gap", "{model}", "{log}", "--json", "{log}"], "log"),
    (["gap", "{model}", "{log}", "--export-model", "{model}"], "model"),
    (["gap", "{model}", "{log}", "--rrd", "{log}"], "log"),
])
def test_an_output_never_overwrites_an_input(argv, victim, inputs, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    before = {k: p.read_bytes() for k, p in inputs.items()}
    argv = [a.format(**{k: str(p) for k, p in inputs.items()}) for a in argv]
    assert main(argv) == 1
    err = _err_lines(capsys)
    assert len(err) == 1 and err[0].startswith(f"vibroscope {argv[0]}: error: ")
    assert "never overwrites an input" in err[0] and str(inputs[victim]) in err[0]
    assert {k: p.read_bytes() for k, p in inputs.items()} == before
    assert not _temps(tmp_path)


def test_analyse_of_a_recording_is_not_an_mcap_file(tiny_log, tmp_path, monkeypatch, capsys):
    """``analyse X.rrd`` fails as not an MCAP file and leaves X.rrd as it was (and writes nothing)."""
    monkeypatch.chdir(tmp_path)
    assert main(["analyse", str(tiny_log), "--rrd", "x.rrd", "--no-figures"]) == 0
    x = tmp_path / "x.rrd"
    data = x.read_bytes()
    capsys.readouterr()
    listing = sorted(p.name for p in tmp_path.iterdir())
    assert main(["analyse", str(x)]) == 1
    err = _err_lines(capsys)
    assert len(err) == 1 and err[0].startswith("vibroscope analyse: error: ") and "MCAP" in err[0], err
    assert x.read_bytes() == data and sorted(p.name for p in tmp_path.iterdir()) == listing


def test_export_model_with_no_mode_says_so(tiny_log, tmp_path, capsys):
    """An input given but no mode in the band: the error says no mode was identified (before: "needs
    residues: an input", though an input was given); nothing is written."""
    out = tmp_path / "m.toml"
    assert main(["modal", str(tiny_log), "--input", "/actuator/force.wrench.force.x", "--fmin", "4", "--fmax", "9",
                 "--export-model", str(out), "--no-rrd", "--no-figures"]) == 1
    err = _err_lines(capsys)
    assert len(err) == 1 and "--export-model: no mode was identified" in err[0] and not out.exists()


def test_ods_above_the_band_is_refused_before_the_report(tiny_log, tmp_path, capsys):
    """--ods beyond the analysed band: one error line and no modes table printed as if all went well
    (before: the report, then the error); --ods beyond --fs / 2 is refused before the log is read."""
    assert main(["analyse", str(tiny_log), "--ods", "150", "--out", str(tmp_path)]) == 1
    cap = capsys.readouterr()
    assert "f_n [Hz]" not in cap.out and "--ods 150: above the analysed band's top" in cap.err
    assert main(["analyse", str(tiny_log), "--fs", "200", "--ods", "150", "--out", str(tmp_path)]) == 1
    assert "above the Nyquist frequency 100 Hz of --fs 200" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_a_log_of_a_few_samples_is_too_short(tmp_path, capsys):
    """Two samples: the error says the log is too short (before: "fmin=500.0 must be below
    fmax=500.0 (Hz)", though no band was given)."""
    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    log = write_ros2_mcap(tmp_path / "two.mcap", Signals(data=np.ones((3, 2)) * [[1], [2], [3]] + [[0, 1]], fs=1000.0,
                                                         channels=[f"/imu.linear_acceleration.{a}" for a in "xyz"],
                                                         t0=1.0))
    assert main(["analyse", str(log), "--out", str(tmp_path / "o")]) == 1
    err = _err_lines(capsys)
    assert len(err) == 1 and "too short to analyse: 2 samples" in err[0]


def test_preload_imports_the_output_libraries_in_the_background_only_when_asked():
    """``preload_outputs`` imports rerun (not pandas: pyarrow is told it is missing, see the next
    test) and pyplot with PIL in a thread that :func:`preloaded` joins; with no output it
    starts nothing (a fresh process each, so that nothing was imported before)."""
    code = ("import sys, threading; from vibroscope.commands._outputs import preload_outputs, preloaded; "
            "preload_outputs(rrd={rrd}, figures={fig}); n = threading.active_count(); preloaded(); "
            "print(n, threading.active_count(), *(m in sys.modules for m in "
            "('rerun', 'pandas', 'matplotlib.pyplot', 'PIL.Image')))")
    run = lambda rrd, fig: subprocess.run([sys.executable, "-c", code.format(rrd=rrd, fig=fig)],  # noqa: E731
                                          capture_output=True, text=True, check=True).stdout.split()
    assert run(True, True) == ["2", "1", "True", "False", "True", "True"]
    assert run(False, True) == ["2", "1", "False", "False", "True", "True"]
    assert run(False, False) == ["1", "1", "False", "False", "False", "False"]


def test_recording_without_pandas_holds_the_samples_and_pandas_still_imports(tmp_path):
    """The command line's rerun preload (``preload(pandas=False)``) keeps pandas out of the
    process: a recording logged afterwards holds every sample exactly (float64) and its
    blueprint, pandas is never imported on the way, and an explicit ``import pandas`` still
    works afterwards (nothing is left blocked); with ``pandas=True`` pyarrow imports it, as
    before (a fresh process each)."""
    pytest.importorskip("pandas")
    code = ("import sys, numpy as np; from vibroscope.viewers.rerun_recording import preload; "
            "preload(pandas={pandas}); from vibroscope.signals import Signals; "
            "from vibroscope.viewers.rerun_view import log_analysis; "
            "x = np.sin(2 * np.pi * 5.0 * np.arange(3000) / 100.0)[None] + 0.25; "
            "log_analysis(signals=Signals(data=x, fs=100.0, channels=['/imu.linear_acceleration.x'], units=['m/s^2']), "
            "rrd_path=sys.argv[1]); print('pandas' in sys.modules); import pandas; print(pandas.Series([1.5]).sum())")
    for pandas in (False, True):
        rrd = tmp_path / f"p{pandas}.rrd"
        out = subprocess.run([sys.executable, "-c", code.format(pandas=pandas), str(rrd)], capture_output=True,
                             text=True, check=True).stdout.split()
        assert out == [str(pandas), "1.5"]
        from vibroscope.viewers.rerun_view import read_rrd

        d = read_rrd(rrd)
        ent = [v for k, v in d.items() if k.startswith("/signals/")]
        assert len(ent) == 1
        x = np.sin(2 * np.pi * 5.0 * np.arange(3000) / 100.0) + 0.25
        np.testing.assert_array_equal(ent[0]["Scalars:scalars"], x)
        assert read_rrd(rrd, blueprint=True).keys() - d.keys()  # the blueprint is there too
