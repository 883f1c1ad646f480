"""Mode sets made elsewhere (issue #20 item 5): a UFF 55 export with its geometry (UFF 2411) as an
LMS Test.Lab export holds it, a kind = "modal" / "lumped" model file and a MODES.json are read,
shown by `vibroscope modal` and compared by `vibroscope compare A B`. The oracle is a known model:
two 3-storey shear chains (10 kg per floor; X 2e4 N/m, Y 3e4 N/m per storey), whose modes are
written with pyuff; a perturbed, shuffled copy has known frequency differences."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from vibroscope.cli import main
from vibroscope.errors import LogFormatError
from vibroscope.io.frf_files import write_modes_uff55
from vibroscope.io.mode_sets import is_mode_set, read_mode_set
from vibroscope.modal import ModalModel, compare_mode_sets, mac
from vibroscope.models import LumpedModel

HEIGHTS = (1.0, 2.0, 3.0)


def tower_modes() -> ModalModel:
    """Six modes of the two chains at points 1+X, 1+Y, ... 3+Y, ascending."""
    mx = LumpedModel.chain([10.0] * 3, [2e4] * 3, [2.0] * 3).modes()
    my = LumpedModel.chain([10.0] * 3, [3e4] * 3, [2.0] * 3).modes()
    f = np.r_[mx.natural_frequencies, my.natural_frequencies]
    z = np.r_[mx.damping_ratios, my.damping_ratios]
    S = np.zeros((6, 6), complex)
    S[:3, 0::2] = mx.shapes
    S[3:, 1::2] = my.shapes
    o = np.argsort(f)
    return ModalModel(natural_frequencies=f[o], damping_ratios=z[o], shapes=S[o],
                      points=[f"{n}+{d}" for n in (1, 2, 3) for d in "XY"], method="test")


def write_lms_export(path, mm: ModalModel):
    """Units (164) and nodes (2411, a base node 4 without a sensor) then one UFF 55 record per mode."""
    import pyuff

    geo = path.with_name(path.stem + "_geo.unv")
    nodes = np.array([1, 2, 3, 4])
    pyuff.UFF(str(geo)).write_sets([
        pyuff.prepare_164(units_code=1, units_description="SI", temp_mode=2, length=1.0, force=1.0, temp=1.0,
                          temp_offset=273.15),
        pyuff.prepare_2411(node_nums=nodes, def_cs=np.zeros(4, int), disp_cs=np.zeros(4, int),
                           color=np.ones(4, int), x=np.zeros(4), y=np.zeros(4), z=np.array([*HEIGHTS, 0.0]))],
        mode="add")
    modes = write_modes_uff55(mm, path.with_name(path.stem + "_modes.unv"))
    path.write_text(geo.read_text() + modes.read_text())
    return path


@pytest.fixture
def lms(tmp_path):
    return write_lms_export(tmp_path / "lms.unv", tower_modes())


def test_uff55_export_with_geometry_is_read(lms):
    mm = tower_modes()
    assert is_mode_set(lms)
    ms = read_mode_set(lms)
    assert ms.format == "uff55" and len(ms.modes) == 6 and ms.modes.points == mm.points
    np.testing.assert_allclose(ms.modes.natural_frequencies, mm.natural_frequencies, rtol=1e-5)
    np.testing.assert_allclose(ms.modes.damping_ratios, mm.damping_ratios, rtol=1e-4)
    np.testing.assert_allclose(np.diag(mac(ms.modes, mm)), 1.0, atol=1e-9)
    # the geometry of the same file: node k at height k, each point along its axis
    np.testing.assert_allclose(ms.coords.xyz[:, 2], np.repeat(HEIGHTS, 2), atol=1e-12)
    np.testing.assert_allclose(ms.coords.directions, np.tile([[1, 0, 0], [0, 1, 0]], (3, 1)))


def test_modal_shows_a_uff55_export(lms, tmp_path, capsys, check_png):
    out = tmp_path / "out"
    assert main(["modal", str(lms), "--out", str(out), "--json", str(tmp_path / "m.json")]) == 0
    text = capsys.readouterr().out
    assert "6 modes at 6 points (uff55" in text and "geometry of 6 points" in text
    assert "no UFF 58 FRF record" not in text
    rows = [float(x) for x in re.findall(r"^\s+\d+\s+([\d.]+)\s+[\d.]+\s+[\d.]+$", text, re.M)]
    np.testing.assert_allclose(rows, tower_modes().natural_frequencies, rtol=5e-5)  # UFF 55 stores 6 digits
    check_png(out / "lms_modal_figures" / "modes.png")
    doc = json.loads((tmp_path / "m.json").read_text())
    assert len(doc["modes"]) == 6
    rrd = out / "lms_modal.rrd"
    pytest.importorskip("rerun")
    from vibroscope.viewers.rerun_view import read_rrd

    ents = read_rrd(rrd)
    shapes = [e for e in ents if e.startswith("/modes/mode_")]
    assert len([e for e in shapes if not e.endswith("undeformed")]) == 6
    # identification options do not apply to a file of modes
    assert main(["modal", str(lms), "--select", "3,4", "--no-rrd", "--no-figures"]) != 0


def test_compare_a_mode_set_with_itself(lms):
    mm = read_mode_set(lms).modes
    c = compare_mode_sets(mm, mm)
    np.testing.assert_allclose(np.diag(c.mac), 1.0, atol=1e-12)
    np.testing.assert_allclose(c.mac, np.eye(6), atol=1e-9)  # uniform masses: orthogonal shapes
    assert c.pairs.tolist() == [[k, k] for k in range(6)]
    np.testing.assert_array_equal(c.frequency_difference_hz, 0.0)
    assert c.matched_by == "name" and not len(c.unpaired_a) and not len(c.unpaired_b)


def test_compare_pairs_a_perturbed_shuffled_copy(lms, tmp_path, capsys, check_png):
    """B: frequencies scaled by known factors, shapes rotated by a complex scale, the modes
    shuffled and mode 3 of A missing: the pairs follow the shapes, not the order."""
    a = tower_modes()
    factor = np.array([1.02, 0.97, 1.05, 1.0, 0.99, 1.03])
    order = [3, 0, 5, 1, 4]  # B's k-th mode is A's order[k]; A's mode 3 (index 2) absent
    fb = (a.natural_frequencies * factor)[order]
    b = ModalModel(natural_frequencies=fb, damping_ratios=a.damping_ratios[order],
                   shapes=a.shapes[order] * (-0.7 + 0.4j), points=a.points, method="model")
    c = compare_mode_sets(a, b)
    expect = sorted((ia, k) for k, ia in enumerate(order))
    assert c.pairs.tolist() == [list(p) for p in expect]
    np.testing.assert_allclose(c.frequency_difference, factor[[p[0] for p in expect]] - 1, atol=1e-12)
    np.testing.assert_allclose(c.frequency_difference_hz,
                               a.natural_frequencies[[p[0] for p in expect]] * (factor[[p[0] for p in expect]] - 1),
                               rtol=1e-12)
    np.testing.assert_allclose(c.mac_pairs, 1.0, atol=1e-12)
    assert c.unpaired_a.tolist() == [2] and c.unpaired_b.tolist() == []
    # the same through the files and the CLI
    pb = write_modes_uff55(b, tmp_path / "model.unv")
    assert main(["compare", str(lms), str(pb), "--out", str(tmp_path), "--json", str(tmp_path / "c.json")]) == 0
    text = capsys.readouterr().out
    assert "+2.00 |" in text and "-3.00 |" in text and "+5.00 |" not in text and "unpaired in A" in text
    doc = json.loads((tmp_path / "c.json").read_text())
    assert [(p["a"], p["b"]) for p in doc["pairs"]] == [(i + 1, j + 1) for i, j in expect]
    np.testing.assert_allclose([p["difference_percent"] for p in doc["pairs"]],
                               100 * (factor[[p[0] for p in expect]] - 1), atol=1e-3)  # UFF: 6 digits
    check_png(tmp_path / "compare_lms_model.png")


def test_model_files_and_modes_json_are_mode_sets(tmp_path, capsys):
    """kind = "lumped": its own modes; kind = "modal": shapes from the modal constants
    (A_r = φ φ_i for receptance residues R_r = φ φ_i / (2 j ω_d)); MODES.json round trip."""
    from vibroscope.modal import modes_document
    from vibroscope.models import Input, Output
    from vibroscope.models.lumped import demo_model
    from vibroscope.models.modal_model import PoleResidueModel
    from vibroscope.models.modelfile import dump_model

    lumped = demo_model()
    dump_model(lumped, tmp_path / "lumped.toml")
    ms = read_mode_set(tmp_path / "lumped.toml")
    md = lumped.modes()
    logged = {o.dof: o.channel for o in lumped.outputs}
    assert ms.format == "model file (lumped)" and ms.modes.points == tuple(logged[d] for d in md.dofs)
    np.testing.assert_allclose(ms.modes.natural_frequencies, md.natural_frequencies, rtol=1e-12)

    phi = np.real(md.shapes)  # (3 modes, 3 DOFs), nearly real for light damping
    wd = 2 * np.pi * md.natural_frequencies * np.sqrt(1 - md.damping_ratios ** 2)
    R = phi[:, :, None] * phi[:, 2][:, None, None] / (2j * wd[:, None, None])  # input at DOF 3
    pr = PoleResidueModel.from_poles_residues(
        md.natural_frequencies, md.damping_ratios, R, inputs=[Input(dof="m3", channel="/f.x")],
        outputs=[Output(d, "displacement", f"/x/{d}.x") for d in md.dofs], name="from the lumped model")
    dump_model(pr, tmp_path / "modal.toml")
    mp = read_mode_set(tmp_path / "modal.toml")
    assert mp.format == "model file (modal)" and mp.modes.points == tuple(f"/x/{d}.x" for d in md.dofs)
    np.testing.assert_allclose(np.diag(mac(mp.modes.shapes, phi)), 1.0, atol=1e-9)
    c = compare_mode_sets(mp.modes, ms.modes)  # no common point name, as many points: by order
    assert c.matched_by == "order" and c.pairs.tolist() == [[0, 0], [1, 1], [2, 2]]
    np.testing.assert_allclose(c.frequency_difference_hz, 0.0, atol=1e-9)

    (tmp_path / "MODES.json").write_text(json.dumps(modes_document(ms.modes)))
    mj = read_mode_set(tmp_path / "MODES.json")
    np.testing.assert_allclose(mj.modes.shapes, ms.modes.shapes, rtol=1e-12)
    assert main(["compare", str(tmp_path / "MODES.json"), str(tmp_path / "modal.toml"), "--out", str(tmp_path)]) == 0
    assert "matched by order" in capsys.readouterr().out
    with pytest.raises(LogFormatError, match="no such file"):
        read_mode_set(tmp_path / "absent.unv")


def test_compare_refuses_sets_without_common_points(lms, tmp_path):
    other = ModalModel(natural_frequencies=[5.0], damping_ratios=[0.01], shapes=[[1.0, 0.5]], points=["a", "b"],
                       method="x")
    with pytest.raises(ValueError, match="share no point name"):
        compare_mode_sets(tower_modes(), other)
    assert main(["compare", str(lms), str(write_modes_uff55(other, tmp_path / "o.unv", node_ids=[7, 8])),
                 "--out", str(tmp_path)]) != 0


@pytest.mark.parametrize("name", ["Sample_UFF58_ascii.uff", "MPSTD_Set001_2024_10_08.uff"])
def test_time_data_uff_points_to_convert(shared_data, name, capsys):
    """pyuff's time-data samples (MIT, ladisk/pyuff): `modal` says to convert them to a log."""
    assert main(["modal", str(shared_data / "uff" / name), "--no-rrd", "--no-figures"]) != 0
    err = capsys.readouterr().err
    assert "time data" in err and "vibroscope convert" in err


def test_shapes_on_a_plane_geometry_are_drawn_in_3d(tmp_path, check_png):
    """A simply supported plate's modes sin(mπx/a) sin(nπy/b) at a 5 x 4 grid: `modal` also writes
    modes_3d.png (the tower above, points on a line, gets modes.png only)."""
    import pyuff

    a, b = 0.6, 0.4
    X, Y = (g.ravel() for g in np.meshgrid(np.linspace(0, a, 5), np.linspace(0, b, 4), indexing="ij"))
    nodes = np.arange(1, X.size + 1)
    mn = [(1, 1), (2, 1), (1, 2), (2, 2)]
    shapes = np.array([np.sin(m * np.pi * X / a) * np.sin(n * np.pi * Y / b) for m, n in mn])
    f = np.array([20 * ((m / a) ** 2 + (n / b) ** 2) for m, n in mn])
    mm = ModalModel(natural_frequencies=f, damping_ratios=np.full(4, 0.01), shapes=shapes,
                    points=[f"{k}+Z" for k in nodes], method="plate")
    geo = tmp_path / "g.unv"
    pyuff.UFF(str(geo)).write_sets([pyuff.prepare_2411(
        node_nums=nodes, def_cs=np.zeros(nodes.size, int), disp_cs=np.zeros(nodes.size, int),
        color=np.ones(nodes.size, int), x=X, y=Y, z=np.zeros(X.size))], mode="add")
    path = tmp_path / "plate.unv"
    path.write_text(geo.read_text() + write_modes_uff55(mm, tmp_path / "m.unv").read_text())
    ms = read_mode_set(path)
    assert ms.coords is not None and len(ms.modes) == 4
    np.testing.assert_allclose(np.diag(compare_mode_sets(ms.modes, mm).mac), 1.0, atol=1e-9)
    assert main(["modal", str(path), "--out", str(tmp_path / "o"), "--no-rrd"]) == 0
    check_png(tmp_path / "o" / "plate_modal_figures" / "modes_3d.png")
    tower = write_lms_export(tmp_path / "lms.unv", tower_modes())
    assert main(["modal", str(tower), "--out", str(tmp_path / "t"), "--no-rrd"]) == 0
    assert not (tmp_path / "t" / "lms_modal_figures" / "modes_3d.png").exists()


def test_modes_beside_time_data_are_shown(lms, shared_data, tmp_path, capsys):
    """An export holding mode shapes and time data (no FRF): `modal` shows the modes."""
    both = tmp_path / "both.unv"
    both.write_text(lms.read_text() + (shared_data / "uff" / "Sample_UFF58_ascii.uff").read_text())
    assert not is_mode_set(both)  # it holds a dataset 58: identification is tried first
    assert main(["modal", str(both), "--no-rrd", "--no-figures"]) == 0
    assert "6 modes at 6 points (uff55" in capsys.readouterr().out
