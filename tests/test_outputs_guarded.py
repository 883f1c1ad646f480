"""Outputs, second pass (issues 20.3, 20.8, 21.3, 21.7): special files are never replaced; an
unwritable folder is found before any work; relative paths go inside ``--out``; hints quote their
paths; ``info --json`` is strict JSON; a closed pipe, SIGTERM and Ctrl-C end a command cleanly;
``--spawn`` starts the viewer rerun-sdk ships or says in one line why not, and never hangs."""

from __future__ import annotations

import json
import os
import shlex
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from vibroscope.cli import main
from vibroscope.commands._outputs import TEMP_MARK, AtomicOutputs, check_outputs, special_kind
from vibroscope.errors import VibroscopeError
from vibroscope.provenance import json_report


def _j(text: str) -> str:
    """A JSON report as vibroscope writes it (its first key the generator), holding `text`."""
    return json.dumps(json_report({"text": text}))

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
NO_DISPLAY = ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")


@pytest.fixture(scope="module")
def tiny_log(tmp_path_factory):
    """A 4 s, 200 Hz demo log (force + 3 Imu), written once; tests must not change it."""
    from vibroscope.commands.demo import make_demo_log

    path = tmp_path_factory.mktemp("tiny") / "tiny.mcap"
    make_demo_log(path, duration=4.0, fs=200.0)
    return path


def _temps(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if TEMP_MARK in p.name]


def _env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in NO_DISPLAY}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")
    env.update(extra)
    return env


def _char_device(tmp_path: Path) -> Path:
    """A character device to aim an output at: a private twin of /dev/null made with mknod when
    allowed (as root, where a regression would otherwise replace the machine's /dev/null), else
    /dev/null itself (which an unprivileged run cannot replace)."""
    twin = tmp_path / "null"
    try:
        os.mknod(twin, stat.S_IFCHR | 0o666, os.stat("/dev/null").st_rdev)
        return twin
    except (PermissionError, AttributeError, OSError):
        if os.geteuid() == 0:  # pragma: no cover - root without mknod (a restricted container)
            pytest.skip("root cannot make a private character device here")
        return Path("/dev/null")


def _snapshot(p: Path):
    st = os.lstat(p)
    return (stat.S_IFMT(st.st_mode), st.st_ino, os.readlink(p) if stat.S_ISLNK(st.st_mode) else None)


@pytest.fixture
def targets(tmp_path):
    """Special files to aim outputs at: a symlink to a regular file, a dangling symlink, a FIFO, a
    character device."""
    victim = tmp_path / "victim.txt"
    victim.write_text("not ours")
    (tmp_path / "link.json").symlink_to(victim)
    (tmp_path / "dangling.json").symlink_to(tmp_path / "nowhere.json")
    os.mkfifo(tmp_path / "fifo.json")
    return {"symlink": (tmp_path / "link.json", "a symbolic link"),
            "dangling": (tmp_path / "dangling.json", "a symbolic link"),
            "fifo": (tmp_path / "fifo.json", "a FIFO"),
            "device": (_char_device(tmp_path), "a character device")}


# ---------------------------------------------------------------- 21.3: special files are refused

@pytest.mark.parametrize("kind", ["symlink", "dangling", "fifo", "device"])
@pytest.mark.parametrize("option", ["--json", "--rrd", "--figures"])
def test_analyse_refuses_a_special_file_as_output_before_any_analysis(kind, option, targets, tiny_log, tmp_path,
                                                                      monkeypatch, capsys):
    target, what = targets[kind]
    before = _snapshot(target)
    monkeypatch.chdir(tmp_path)
    import vibroscope.commands.analyse as an

    def no_analysis(*a, **k):  # the refusal must come before the log is read
        raise AssertionError("analysis ran")

    monkeypatch.setattr(an, "analyse_log", no_analysis)
    assert main(["analyse", str(tiny_log), option, str(target), "--no-figures" if option != "--figures"
                 else "--no-rrd"]) == 1
    cap = capsys.readouterr()
    err = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("vibroscope analyse: error: ") and str(target) in err[0], err
    assert what in err[0] and "Traceback" not in cap.err
    assert cap.out == ""  # nothing analysed, nothing reported
    assert _snapshot(target) == before
    assert (tmp_path / "victim.txt").read_text() == "not ours"
    assert not (tmp_path / "nowhere.json").exists() and not _temps(tmp_path)


@pytest.mark.parametrize("argv", [
    ["modal", "{log}", "--json", "{t}", "--no-figures", "--no-rrd"],
    ["modal", "{log}", "--uff55", "{t}", "--no-figures", "--no-rrd"],
    ["info", "{log}"],  # (info writes no file: not refused, listed to show the contrast is the option's)
])
def test_other_commands_refuse_special_files(argv, targets, tiny_log, tmp_path, monkeypatch, capsys):
    target, what = targets["fifo"]
    monkeypatch.chdir(tmp_path)
    args = [a.format(log=tiny_log, t=target) for a in argv]
    status = main(args)
    cap = capsys.readouterr()
    if argv[0] == "info":
        assert status == 0
        return
    assert status == 1 and what in cap.err and str(target) in cap.err and cap.out == ""
    assert stat.S_ISFIFO(os.lstat(target).st_mode)


def test_simulate_refuses_a_device_as_out(targets, tmp_path, capsys):
    model = tmp_path / "m.toml"
    model.write_text('kind = "lumped"\n[[dof]]\nname = "m1"\nmass = 1.0\n[[element]]\ntype = "spring"\n'
                     'between = ["m1", "ground"]\nk = 1.0e4\n[[output]]\nchannel = "/imu/m1.linear_acceleration.x"\n'
                     'dof = "m1"\nquantity = "acceleration"\n')
    target, what = targets["device"]
    before = _snapshot(target)
    assert main(["simulate", str(model), "--excitation", "step:amplitude=1", "--out", str(target),
                 "--duration", "1"]) == 1
    cap = capsys.readouterr()
    assert what in cap.err and str(target) in cap.err and cap.out == ""
    assert _snapshot(target) == before


def test_special_kind_and_check_outputs(targets, tmp_path):
    for target, what in targets.values():
        assert special_kind(target) == what
        with pytest.raises(VibroscopeError, match=f"is {what}: only vibroscope's own earlier outputs"):
            check_outputs({"--json": target}, {})
    regular = tmp_path / "earlier.json"
    regular.write_text(_j("earlier"))
    assert special_kind(regular) is None and special_kind(tmp_path) is None and special_kind(tmp_path / "no") is None
    check_outputs({"--json": regular, "--figures": tmp_path / "figs"}, {})  # an earlier output: fine
    with pytest.raises(VibroscopeError, match="is a folder: give a file name"):
        check_outputs({"--json": tmp_path}, {})
    with pytest.raises(VibroscopeError, match="is a file, not a folder"):
        check_outputs({"--figures": regular}, {})


def test_commit_refuses_a_target_that_became_special_and_keeps_the_set_whole(tmp_path, capsys):
    """A final path turned into a FIFO between the check and the commit: nothing is moved, the
    earlier outputs stay, no temporary is left."""
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(_j("earlier a"))
    with pytest.raises(VibroscopeError, match="is a FIFO"):
        with AtomicOutputs() as tx:
            tx.file(a).write_text("new a")
            tx.file(b).write_text("new b")
            (tx.directory(tmp_path / "figs") / "psd.png").write_bytes(b"png")
            os.mkfifo(b)
    assert a.read_text() == _j("earlier a") and stat.S_ISFIFO(os.lstat(b).st_mode)
    assert not (tmp_path / "figs").exists() and not _temps(tmp_path)
    # a figures folder holding a link among its PNGs is merged into, never swapped away whole
    figs = tmp_path / "figs2"
    figs.mkdir()
    (figs / "old.png").write_bytes(b"\x89PNG\r\n\x1a\n\0\0\0\x18tEXtSoftware\0vibroscope test\0\0\0\0")
    (figs / "linked.png").symlink_to(tmp_path / "a.json")
    with AtomicOutputs() as tx:
        (tx.directory(figs) / "psd.png").write_bytes(b"psd")
    assert (figs / "linked.png").is_symlink() and (figs / "old.png").exists() and (figs / "psd.png").exists()
    with pytest.raises(VibroscopeError, match="is a symbolic link"):
        with AtomicOutputs() as tx:
            (tx.directory(figs) / "linked.png").write_bytes(b"figure")
    assert (figs / "linked.png").is_symlink() and a.read_text() == _j("earlier a") and not _temps(tmp_path)


def test_a_failed_move_puts_the_earlier_outputs_back(tmp_path, monkeypatch):
    """All or none: when the second move fails, the first output is put back as it was."""
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(_j("earlier a"))
    b.write_text(_j("earlier b"))
    real = os.replace
    calls = []

    def flaky(src, dst):
        calls.append((Path(src).name, Path(dst).name))
        if Path(dst) == b and TEMP_MARK in Path(src).name and ".old" not in Path(src).name:
            raise OSError(28, "No space left on device")
        return real(src, dst)

    monkeypatch.setattr(os, "replace", flaky)
    with pytest.raises(OSError, match="No space"):
        with AtomicOutputs(stream=open(os.devnull, "w")) as tx:
            tx.file(a).write_text("new a")
            tx.file(b).write_text("new b")
    monkeypatch.setattr(os, "replace", real)
    assert a.read_text() == _j("earlier a") and b.read_text() == _j("earlier b") and not _temps(tmp_path)


def test_a_signal_during_the_moves_is_held_until_the_set_is_complete(tmp_path):
    """SIGINT arriving in the middle of the moves: every output is in place, then Ctrl-C is raised."""
    outs = [tmp_path / f"o{k}.json" for k in range(4)]
    real = os.replace
    n = []

    def replace_then_interrupt(src, dst):
        real(src, dst)
        n.append(dst)
        if len(n) == 1:
            os.kill(os.getpid(), signal.SIGINT)

    # the precondition: Python's own Ctrl-C handler (in one full CI run an earlier test had left
    # another one installed, and no KeyboardInterrupt could come)
    old_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    os.replace = replace_then_interrupt
    try:
        with pytest.raises(KeyboardInterrupt):
            with AtomicOutputs() as tx:
                for o in outs:
                    tx.file(o).write_text(o.name)
    finally:
        os.replace = real
        signal.signal(signal.SIGINT, old_int)
    assert [o.read_text() for o in outs] == [o.name for o in outs] and not _temps(tmp_path)


# ---------------------------------------------------------------- 20.8 / 21.7: checked before any work

def test_unwritable_out_is_refused_before_any_work(tiny_log, tmp_path, monkeypatch, capsys):
    import vibroscope.commands.analyse as an

    monkeypatch.setattr(an, "analyse_log", lambda *a, **k: pytest.fail("analysis ran"))
    a_file = tmp_path / "plain.txt"
    a_file.write_text("x")
    cases = [(str(a_file / "sub"), "cannot create a folder under"), ("/proc/vibroscope-out", "cannot write in /proc")]
    if os.geteuid() != 0:  # root writes in a read-only-mode folder: only a read-only file system stops it
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        cases.append((str(ro), "cannot write in"))
    for out, msg in cases:
        assert main(["analyse", str(tiny_log), "--out", out]) == 1
        cap = capsys.readouterr()
        assert cap.out == "" and msg in cap.err and len(cap.err.strip().splitlines()) == 1, (out, cap.err)
        assert "Traceback" not in cap.err and "FileNotFoundError" not in cap.err
    # an output file in a folder under a file: refused before the analysis, one line
    assert main(["analyse", str(tiny_log), "--json", str(a_file / "s.json"), "--no-rrd", "--no-figures"]) == 1
    cap = capsys.readouterr()
    assert cap.out == "" and "--json" in cap.err and "cannot create a folder under" in cap.err


def test_relative_outputs_go_inside_out_and_hints_are_quoted(tiny_log, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "my results"
    assert main(["analyse", str(tiny_log), "--out", str(out), "--json", "s.json", "--rrd", "r 1.rrd",
                 "--no-figures"]) == 0
    text = capsys.readouterr().out
    assert (out / "s.json").is_file() and (out / "r 1.rrd").is_file()
    assert not (tmp_path / "s.json").exists() and not (tmp_path / "r 1.rrd").exists()
    json.loads((out / "s.json").read_text())
    hint = [ln for ln in text.splitlines() if "open with: rerun" in ln]
    assert len(hint) == 1
    cmd = hint[0].split("open with: ", 1)[1].rstrip(")")
    assert shlex.split(cmd) == ["rerun", str(out / "r 1.rrd")]
    # an absolute path stays where it is named
    absolute = tmp_path / "abs.json"
    assert main(["analyse", str(tiny_log), "--out", str(out), "--json", str(absolute), "--no-rrd",
                 "--no-figures"]) == 0
    capsys.readouterr()
    assert absolute.is_file()


def test_modal_names_no_json_it_was_not_asked_for(tmp_path, capsys):
    from vibroscope.commands.modal import _print_modes
    from vibroscope.modal import ModalModel
    from vibroscope.modal.automatic import Identification
    from vibroscope.modal.selection import RejectedMode as Rejected

    import numpy as np

    rej = Rejected(12.5, 0.02, "not stable across orders")
    ident = Identification(ModalModel(natural_frequencies=np.array([5.0]), damping_ratios=np.array([0.01]),
                                      shapes=np.ones((1, 2)), points=("a", "b"), method="lscf"),
                           [rej], None, {})
    _print_modes(ident, None)
    out = capsys.readouterr().out
    assert "MODES.json" not in out and "listed with --json" in out
    _print_modes(ident, tmp_path / "m.json")
    assert f"in {tmp_path / 'm.json'}" in capsys.readouterr().out


def test_info_json_is_strict_for_topics_of_one_message(tmp_path, capsys):
    logs = sorted((SHARED / "mcap" / "conformance" / "OneMessage").glob("*.mcap"))[:1]
    if not logs:
        pytest.skip("shared data not available")
    assert main(["info", str(logs[0]), "--json"]) == 0
    text = capsys.readouterr().out

    def refuse(c):
        raise ValueError(f"bare {c} in the JSON")

    doc = json.loads(text, parse_constant=refuse)
    topics = doc["topics"]
    assert topics and any(t.get("message_count") == 1 for t in topics)
    assert all(t["rate_hz"] is None for t in topics if t.get("message_count", 0) < 2)


def test_info_into_a_closed_pipe_ends_quietly():
    log = SHARED / "mcap" / "capstan" / "bagfile_0.mcap"
    if not log.exists():
        pytest.skip("shared data not available")
    proc = subprocess.Popen([sys.executable, "-m", "vibroscope.cli", "info", str(log)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=_env())
    proc.stdout.close()  # the reader goes away before the first line (as `| head` does after one)
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert "Traceback" not in err and "BrokenPipe" not in err and "Exception ignored" not in err, err


# ---------------------------------------------------------------- --stream: all outputs or none

def test_stream_interrupted_while_drawing_leaves_no_summary(tiny_log, tmp_path, monkeypatch, capsys):
    import vibroscope.viewers.figures as vf

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(vf, "figure_jobs", interrupted)
    js = tmp_path / "s.json"
    assert main(["analyse", str(tiny_log), "--stream", "--json", str(js), "--out", str(tmp_path)]) == 130
    capsys.readouterr()
    assert not js.exists() and not (tmp_path / "tiny_analyse.rrd").exists()
    assert not (tmp_path / "tiny_analyse_figures").exists() and not _temps(tmp_path)
    monkeypatch.undo()
    assert main(["analyse", str(tiny_log), "--stream", "--json", str(js), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert json.loads(js.read_text())["settings"]["streamed"] is True and f"summary: {js}" in out
    assert (tmp_path / "tiny_analyse.rrd").is_file() and any((tmp_path / "tiny_analyse_figures").glob("*.png"))


# ---------------------------------------------------------------- SIGTERM cleans up like Ctrl-C

def test_sigterm_during_analyse_cleans_up(tiny_log, tmp_path):
    earlier = tmp_path / "tiny_analyse.rrd"
    earlier.write_bytes(b"earlier complete output")
    proc = subprocess.Popen([sys.executable, "-m", "vibroscope.cli", "analyse", str(tiny_log)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    deadline = time.monotonic() + 90
    while proc.poll() is None and not _temps(tmp_path) and time.monotonic() < deadline:
        time.sleep(0.005)
    if proc.poll() is not None or not _temps(tmp_path):
        proc.kill()
        proc.communicate()
        pytest.skip("the run ended before its outputs were being written: timing unreliable here")
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    if proc.returncode == 0:
        pytest.skip("SIGTERM arrived after the outputs were complete: timing unreliable here")
    assert proc.returncode == 143, err
    assert "vibroscope analyse: terminated" in err and "Traceback" not in err
    assert earlier.read_bytes() == b"earlier complete output"
    assert not (tmp_path / "tiny_analyse_figures").exists() and not _temps(tmp_path)


# ---------------------------------------------------------------- 20.3: --spawn never hangs

def _port_free(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) != 0


def test_spawn_without_a_display_says_why_in_one_line_and_carries_on(tiny_log, tmp_path):
    from vibroscope.viewers.rerun_view import VIEWER_PORT

    if not _port_free(VIEWER_PORT):
        pytest.skip(f"a program listens on {VIEWER_PORT}: it would be taken as a running viewer")
    t = time.monotonic()
    res = subprocess.run([sys.executable, "-m", "vibroscope.cli", "analyse", str(tiny_log), "--spawn",
                          "--no-figures"], cwd=tmp_path, capture_output=True, text=True, env=_env(), timeout=180)
    assert res.returncode == 0, res.stderr
    err = [ln for ln in res.stderr.splitlines() if ln.strip()]
    spawn = [ln for ln in err if "--spawn" in ln]
    assert len(spawn) == 1 and spawn[0].startswith("vibroscope analyse: warning: --spawn: no rerun viewer opened: "
                                                   "no display"), err
    assert "Rerun is disabled" not in res.stderr and "Traceback" not in res.stderr
    assert (tmp_path / "tiny_analyse.rrd").is_file() and not _temps(tmp_path)
    assert time.monotonic() - t < 170


def _fake_viewer(tmp_path: Path, body: str) -> str:
    exe = tmp_path / "rerun"
    exe.write_text(f"#!{sys.executable}\nimport sys, time\n{body}\n")
    exe.chmod(0o755)
    return str(exe)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_open_in_viewer_starts_the_venv_viewer_and_never_waits_on_it(tmp_path, monkeypatch):
    import vibroscope.viewers.rerun_view as rv

    exe = rv.viewer_executable()
    assert exe is not None  # rerun-sdk ships one (the [rerun] extra is installed here)
    if Path(sys.executable).parent.joinpath("rerun").exists():
        assert exe == str(Path(sys.executable).parent / "rerun")  # the venv's, not whatever is on PATH
    port = _free_port()
    monkeypatch.setenv("DISPLAY", ":99")
    rrd = tmp_path / "a b.rrd"
    rrd.write_bytes(b"x")
    dies = _fake_viewer(tmp_path, "print('\\x1b[31mError: Failed to open connection to X server\\x1b[0m', "
                                  "file=sys.stderr)\nsys.exit(1)")
    t = time.monotonic()
    why = rv.open_in_viewer(rrd, port=port, executable=dies)
    assert why == f"{dies} ended at start (status 1): Error: Failed to open connection to X server"
    assert time.monotonic() - t < 10
    args = tmp_path / "args.json"
    hangs = _fake_viewer(tmp_path, f"import json; json.dump(sys.argv[1:], open({str(args)!r}, 'w'))\n"
                                   "time.sleep(20)")
    t = time.monotonic()
    assert rv.open_in_viewer(rrd, port=port, executable=hangs) is None  # a viewer that stays: it took the file
    assert time.monotonic() - t < 10  # and the command does not wait for it
    assert json.loads(args.read_text()) == ["--port", str(port), str(rrd)]
    handed = _fake_viewer(tmp_path, "sys.exit(0)")  # rerun handing the file to a running viewer
    assert rv.open_in_viewer(rrd, port=port, executable=handed) is None
    for v in NO_DISPLAY:
        monkeypatch.delenv(v, raising=False)
    if sys.platform.startswith("linux"):
        assert rv.open_in_viewer(rrd, port=port, executable=dies) == (
            "no display (DISPLAY and WAYLAND_DISPLAY are not set), so no viewer window can open")


def test_spawn_with_no_rrd_shows_a_file_of_its_own(tiny_log, tmp_path, monkeypatch, capsys):
    """``--spawn --no-rrd``: nothing is written among the outputs; the viewer is handed a complete
    recording in the system's temporary folder."""
    import vibroscope.viewers.rerun_view as rv
    import vibroscope.viewers.rerun_viewer as viewer  # where show_recording looks open_in_viewer up

    seen = []
    monkeypatch.setattr(viewer, "open_in_viewer", lambda path, **k: seen.append(Path(path)) or None)
    monkeypatch.chdir(tmp_path)
    assert main(["analyse", str(tiny_log), "--spawn", "--no-rrd", "--no-figures"]) == 0
    capsys.readouterr()
    assert len(seen) == 1 and seen[0].is_file() and seen[0].suffix == ".rrd" and tmp_path not in seen[0].parents
    assert rv.read_rrd(seen[0])  # complete: rerun reads it back
    assert sorted(p.name for p in tmp_path.iterdir()) == [] and not _temps(tmp_path)
    # with a recording among the outputs, the viewer gets it under its final name, after the commit
    assert main(["analyse", str(tiny_log), "--spawn", "--no-figures"]) == 0
    capsys.readouterr()
    assert seen[1] == tmp_path / "tiny_analyse.rrd" and rv.read_rrd(seen[1])
