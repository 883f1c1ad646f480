"""Issue 21.3: only files vibroscope wrote are replaced (the mark of each format,
:mod:`vibroscope.provenance`); a foreign regular file, a link, a FIFO is refused, named, in one line,
before any work, and left as it was."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import numpy as np
import pytest

from vibroscope.cli import main
from vibroscope.commands._outputs import TEMP_MARK, AtomicOutputs, check_ours, check_outputs
from vibroscope.errors import VibroscopeError
from vibroscope.provenance import GENERATOR, json_report, toml_header, uff_header, written_by_vibroscope

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


def _snapshot(p: Path):
    st = os.lstat(p)
    data = p.read_bytes() if stat.S_ISREG(st.st_mode) else None
    return stat.S_IFMT(st.st_mode), st.st_ino, os.readlink(p) if stat.S_ISLNK(st.st_mode) else None, data


def _foreign(tmp_path: Path, kind: str, name: str) -> Path:
    """Something at `name` that vibroscope did not write: a regular file, a symlink to one, a FIFO."""
    p = tmp_path / name
    if kind == "foreign":
        p.write_bytes(b"a file of someone else's\n")
    elif kind == "symlink":
        victim = tmp_path / "victim.txt"
        victim.write_text("not ours")
        p.symlink_to(victim)
    elif kind == "fifo":
        os.mkfifo(p)
    return p


# ---------------------------------------------------------------- the marks, format by format

def test_every_writer_marks_its_file_and_foreign_files_are_not_taken_for_ours(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mcap.writer import Writer

    from vibroscope.io.mcap_write import write_ros2_mcap
    from vibroscope.signals import Signals
    from vibroscope.viewers.figures import save_figure as _save

    ours, theirs = [], []
    fig = plt.figure()
    fig.gca().plot([0, 1])
    ours.append(_save(fig, tmp_path / "ours.png"))
    fig = plt.figure()
    fig.gca().plot([0, 1])
    fig.savefig(tmp_path / "theirs.png")  # matplotlib's own PNG (Software: Matplotlib ...)
    plt.close(fig)
    theirs.append(tmp_path / "theirs.png")
    ours.append(write_ros2_mcap(tmp_path / "ours.mcap", Signals(data=np.zeros((1, 50)), fs=100.0, channels=["/a.x"],
                                                                units=["m"])))
    with open(tmp_path / "theirs.mcap", "wb") as fh:  # the mcap library's own writer
        w = Writer(fh)
        w.start(profile="", library="someone else")
        w.finish()
    theirs.append(tmp_path / "theirs.mcap")
    (tmp_path / "ours.json").write_text(json.dumps(json_report({"modes": []}), indent=2))
    ours.append(tmp_path / "ours.json")
    (tmp_path / "theirs.json").write_text(json.dumps({"modes": [], "generator": "vibroscope"}))  # not the first key
    theirs.append(tmp_path / "theirs.json")
    (tmp_path / "ours.toml").write_text(toml_header() + 'kind = "modal"\n')
    ours.append(tmp_path / "ours.toml")
    (tmp_path / "theirs.toml").write_text('kind = "modal"  # vibroscope\n')
    theirs.append(tmp_path / "theirs.toml")
    (tmp_path / "theirs.rrd").write_bytes(b"RRF2" + bytes(64) + b"another-application")
    theirs.append(tmp_path / "theirs.rrd")
    (tmp_path / "notes.txt").write_text("vibroscope\n")
    theirs.append(tmp_path / "notes.txt")
    os.mkfifo(tmp_path / "fifo.json")  # never opened (it would block)
    theirs.append(tmp_path / "fifo.json")
    (tmp_path / "link.json").symlink_to(tmp_path / "ours.json")  # a link is not a file we wrote
    theirs.append(tmp_path / "link.json")
    theirs += [tmp_path / "nothing.json", tmp_path]
    assert [p for p in ours if not written_by_vibroscope(p)] == []
    assert [p for p in theirs if written_by_vibroscope(p)] == []
    assert json.loads((tmp_path / "ours.json").read_text()) == {"generator": GENERATOR, "modes": []}


def test_uff_files_carry_a_dataset_151_and_read_back_the_same(tmp_path):
    """The dataset 151 (header) put before UFF 15 and 58 changes nothing that the readers return."""
    from vibroscope.commands.modal import _mark_uff
    from vibroscope.io.frf_files import read_frf, read_geometry, write_frf_uff58, write_geometry_uff15
    from vibroscope.spectral import FRF

    xyz = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.1]])
    a = write_geometry_uff15(tmp_path / "a.uff", [1, 2], xyz)
    b = write_geometry_uff15(tmp_path / "b.uff", [1, 2], xyz)
    _mark_uff(b, uff_header())
    assert not written_by_vibroscope(a) and written_by_vibroscope(b)
    for x, y in zip(read_geometry(a), read_geometry(b)):
        np.testing.assert_array_equal(x, y)
    f = np.linspace(1.0, 50.0, 50)
    H = (1.0 / (1.0 - (f / 20.0) ** 2 + 0.1j * f / 20.0))[:, None, None]
    frf = FRF(frequencies=f, H=H, coherence=np.ones((50, 1)), inputs=("2+X",), outputs=("1+X",), estimator="H1")
    a = write_frf_uff58(frf, tmp_path / "a58.uff")
    b = write_frf_uff58(frf, tmp_path / "b58.uff")
    _mark_uff(b, uff_header())
    assert written_by_vibroscope(b) and not written_by_vibroscope(a)
    ra, rb = read_frf(a), read_frf(b)
    np.testing.assert_array_equal(ra.H, rb.H)
    assert ra.outputs == rb.outputs and ra.inputs == rb.inputs
    # UFF 55 mode shapes are known by their ID line 2 ("vibroscope mode shapes"), no header needed
    from vibroscope.io.frf_files import write_modes_uff55
    from vibroscope.modal import ModalModel

    mm = ModalModel(natural_frequencies=np.array([10.0, 20.0]), damping_ratios=np.array([0.01, 0.02]),
                    shapes=np.array([[1, 0.5], [0.3, 1]], complex), points=("a", "b"), method="lscf")
    assert written_by_vibroscope(write_modes_uff55(mm, tmp_path / "m55.uff"))


def test_check_outputs_and_the_commit_refuse_a_foreign_file_and_keep_it(tmp_path):
    theirs = tmp_path / "r.json"
    theirs.write_text('{"mine": 1}')
    with pytest.raises(VibroscopeError, match=r"^--json: not written by vibroscope: .*r\.json; remove it"):
        check_outputs({"--json": theirs}, {})
    with pytest.raises(VibroscopeError, match="not written by vibroscope"):
        check_ours(theirs, "--json")
    with pytest.raises(VibroscopeError, match="not written by vibroscope"):  # the second guard, at tx.file
        with AtomicOutputs() as tx:
            tx.file(theirs).write_text(json.dumps(json_report({})))
    assert theirs.read_text() == '{"mine": 1}' and not _temps(tmp_path)
    # a file that became foreign between the plan and the commit: nothing moves
    ours = tmp_path / "o.json"
    ours.write_text(json.dumps(json_report({"v": 1})))
    with pytest.raises(VibroscopeError, match="not written by vibroscope"):
        with AtomicOutputs() as tx:
            tx.file(ours).write_text(json.dumps(json_report({"v": 2})))
            ours.write_text("edited by hand")
    assert ours.read_text() == "edited by hand" and not _temps(tmp_path)


def test_a_figures_folder_with_a_foreign_png_is_refused_and_kept(tmp_path):
    figs = tmp_path / "figs"
    figs.mkdir()
    (figs / "notes.txt").write_text("kept")  # not a figure: never touched, not a reason to refuse
    check_outputs({"--figures": figs}, {})
    (figs / "holiday.png").write_bytes(b"\x89PNG\r\n\x1a\nsomeone else's picture")
    with pytest.raises(VibroscopeError, match=r"^--figures .*figs: not written by vibroscope: .*holiday\.png"):
        check_outputs({"--figures": figs}, {})
    # the commit's second guard: a foreign PNG of the same name is never replaced; the folder is merged into
    with pytest.raises(VibroscopeError, match="not written by vibroscope"):
        with AtomicOutputs() as tx:
            (tx.directory(figs) / "holiday.png").write_bytes(b"figure")
    with AtomicOutputs() as tx:
        (tx.directory(figs) / "psd.png").write_bytes(b"figure")
    assert (figs / "holiday.png").read_bytes().endswith(b"someone else's picture")
    assert sorted(p.name for p in figs.iterdir()) == ["holiday.png", "notes.txt", "psd.png"] and not _temps(tmp_path)


# ---------------------------------------------------------------- the commands

@pytest.mark.parametrize("kind", ["foreign", "symlink", "fifo"])
@pytest.mark.parametrize("option", ["--json", "--rrd", "--figures"])
def test_analyse_refuses_what_it_did_not_write_before_any_work(kind, option, tiny_log, tmp_path, monkeypatch,
                                                               capsys):
    if option == "--figures":  # a figure inside the figures folder
        (tmp_path / "figs").mkdir()
        target, arg = _foreign(tmp_path / "figs", kind, "psd.png"), tmp_path / "figs"
    else:
        target = arg = _foreign(tmp_path, kind, "out.json" if option == "--json" else "out.rrd")
    before = _snapshot(target)
    monkeypatch.chdir(tmp_path)
    import vibroscope.commands.analyse as an

    def no_analysis(*a, **k):  # the refusal comes before the log is read
        raise AssertionError("analysis ran")

    monkeypatch.setattr(an, "analyse_log", no_analysis)
    assert main(["analyse", str(tiny_log), option, str(arg), "--no-figures" if option != "--figures"
                 else "--no-rrd"]) == 1
    cap = capsys.readouterr()
    err = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("vibroscope analyse: error: ") and str(target) in err[0], err
    want = {"foreign": "not written by vibroscope", "symlink": "is a symbolic link", "fifo": "is a FIFO"}[kind]
    assert want in err[0] and cap.out == ""
    assert _snapshot(target) == before and not _temps(tmp_path)


def test_analyse_replaces_its_own_earlier_outputs(tiny_log, tmp_path, capsys):
    js, rrd, figs = tmp_path / "s.json", tmp_path / "s.rrd", tmp_path / "figs"
    argv = ["analyse", str(tiny_log), "--json", str(js), "--rrd", str(rrd), "--figures", str(figs)]
    assert main(argv) == 0
    assert "replacing" not in capsys.readouterr().out
    outs = [js, rrd, *sorted(figs.iterdir())]
    assert len(outs) > 3 and all(written_by_vibroscope(p) for p in outs), [p for p in outs if not
                                                                          written_by_vibroscope(p)]
    assert json.loads(js.read_text())["generator"] == GENERATOR
    assert main(argv) == 0
    out = capsys.readouterr().out
    for p in (js, rrd, figs):
        assert f"replacing {p} (earlier output)" in out
    assert all(written_by_vibroscope(p) for p in [js, rrd, *figs.iterdir()]) and not _temps(tmp_path)


@pytest.mark.parametrize("kind", ["foreign", "symlink", "fifo", None])
def test_simulate_out_only_replaces_its_own_log(kind, tmp_path, capsys):
    model = tmp_path / "m.toml"
    model.write_text(MODEL)
    argv = ["simulate", str(model), "--excitation", "step:amplitude=1", "--duration", "0.5", "--out"]
    if kind is None:  # our own earlier log
        out = tmp_path / "earlier.mcap"
        assert main([*argv, str(out)]) == 0 and written_by_vibroscope(out)
        capsys.readouterr()
        assert main([*argv, str(out)]) == 0
        assert f"replacing {out} (earlier output)" in capsys.readouterr().out and written_by_vibroscope(out)
        return
    out = _foreign(tmp_path, kind, "out.mcap")
    before = _snapshot(out)
    assert main([*argv, str(out)]) == 1
    cap = capsys.readouterr()
    err = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert len(err) == 1 and str(out) in err[0] and "--out" in err[0] and cap.out == "", (err, cap.out)
    assert _snapshot(out) == before and not _temps(tmp_path)


@pytest.mark.parametrize("kind", ["foreign", "symlink", "fifo", None])
def test_convert_out_only_replaces_its_own_log(kind, tmp_path, capsys):
    src = tmp_path / "in.csv"
    src.write_text("t,a\n" + "".join(f"{k / 100:.2f},{np.sin(k / 5):.6f}\n" for k in range(64)))
    if kind is None:
        out = tmp_path / "earlier.mcap"
        assert main(["convert", str(src), str(out)]) == 0 and written_by_vibroscope(out)
        assert main(["convert", str(src), str(out)]) == 0 and written_by_vibroscope(out)
        return
    out = _foreign(tmp_path, kind, "out.mcap")
    before = _snapshot(out)
    assert main(["convert", str(src), str(out)]) == 1
    cap = capsys.readouterr()
    err = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert len(err) == 1 and str(out) in err[0] and cap.out == "", (err, cap.out)
    assert _snapshot(out) == before and not _temps(tmp_path)


def test_modal_outputs_are_marked_read_back_and_replaced_by_the_next_run(tmp_path, capsys):
    """UFF 58 / 15 (with their dataset 151), UFF 55, the model file (its first comment line) and the JSON:
    each read back by its reader, known as vibroscope's, and replaced by the same command run again."""
    from vibroscope.commands.demo import make_demo_log
    from vibroscope.io.frf_files import read_frf, read_geometry
    from vibroscope.models.modelfile import load_model

    log = tmp_path / "demo.mcap"  # long enough for LSCF to find the demo's three modes
    make_demo_log(log, duration=20.0, fs=500.0)

    outs = {o: tmp_path / n for o, n in (("--json", "m.json"), ("--uff58", "h.uff"), ("--uff15", "g.uff"),
                                         ("--uff55", "m55.uff"), ("--export-model", "m.toml"))}
    argv = ["modal", str(log), "--input", "/actuator/force.wrench.force.x", "--no-figures", "--no-rrd"]
    for o, p in outs.items():
        argv += [o, str(p)]
    assert main(argv) == 0
    capsys.readouterr()
    assert [p for p in outs.values() if not written_by_vibroscope(p)] == []
    h = read_frf(outs["--uff58"])
    assert h.H.shape[1] == 3 and h.inputs == ("/actuator/force.wrench.force.x",)
    assert read_geometry(outs["--uff15"])[1].shape == (3, 3)
    assert outs["--export-model"].read_text().startswith(toml_header())
    assert len(load_model(outs["--export-model"]).inputs) == 1
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert all(f"replacing {p} (earlier output)" in out for p in outs.values()), out
