"""FRF, mode and geometry files: the Southampton shear-frame FRFs (Cristallo, BSD-3), pyuff's
sample files and ``meas_point_*.txt`` FRFs (ladisk/pyuff, MIT), and synthetic UFF 58/55/15/2411
files written here."""

from __future__ import annotations

import numpy as np
import pytest

from vibroscope.errors import LogFormatError
from vibroscope.io.frf_files import (
    read_frf,
    read_geometry,
    read_modes_uff55,
    write_frf_uff58,
    write_geometry_uff15,
    write_modes_uff55,
)
from vibroscope.modal._results import ModalModel
from vibroscope.spectral._results import FRF


def _sdof_frf(f, fn, zeta):
    """Accelerance of a unit-mass SDOF oscillator, -ω² / (ωn² - ω² + 2jζωnω) in (m/s²)/N."""
    w, wn = 2 * np.pi * f, 2 * np.pi * fn
    return -(w**2) / (wn**2 - w**2 + 2j * zeta * wn * w)


def _synthetic_frf(outputs=("1+Z", "2+Z", "3-X"), inputs=("1+Z",), n=401, df=0.25, coherence=True):
    f = np.arange(n) * df
    H = np.empty((n, len(outputs), len(inputs)), complex)
    for o in range(len(outputs)):
        for i in range(len(inputs)):
            H[:, o, i] = (o + 1 + 0.5 * i) * _sdof_frf(f, 12.0 + 7 * o, 0.02)
    coh = np.clip(0.9 + 0.05 * np.cos(f[:, None] / 7 + np.arange(len(outputs))), 0, 1) if coherence \
        else np.full((n, len(outputs)), np.nan)
    return FRF(frequencies=f, H=H, coherence=coh, inputs=inputs, outputs=outputs, estimator="H1", kind="accelerance",
               units="m/s^2/N", settings={})


# --- the Southampton shear frame: measured complex FRFs ------------------------------------

def _band_peak(frf, fmin, fmax):
    f = frf.frequencies
    m = (f >= fmin) & (f <= fmax)
    return f[m][np.argmax(np.abs(frf.H[m, :, 0]), axis=0)]


def test_southampton_experimental(shared_data):
    """``Experimental.csv``: 3 floors, 0.03125 Hz steps to 128 Hz; first mode near 6.50 Hz
    (data/README: measured modes 6.50, 17.47, 26.50 Hz)."""
    frf = read_frf(shared_data / "southampton" / "frfs" / "Experimental.csv")
    assert frf.H.shape == (4096, 3, 1) and frf.outputs == ("1", "2", "3") and frf.inputs == ("input",)
    assert np.allclose(np.diff(frf.frequencies), 0.03125) and frf.frequencies[0] == 0.03125
    assert frf.frequencies[-1] == 128.0
    assert np.all(np.isfinite(frf.H)) and np.iscomplexobj(frf.H)
    assert np.all(np.isnan(frf.coherence)) and frf.kind is None
    assert np.all(np.abs(_band_peak(frf, 3.0, 10.0) - 6.5) <= 0.2)
    assert frf.settings["format"] == "csv" and frf.settings["frequency_axis"] == "file"


def test_southampton_hammer(shared_data):
    """``Hammer.csv``: real frequency column, 0.124875 Hz steps; the hammer test puts the first
    mode at 6.24 Hz, within 0.3 Hz of the shaker tests' 6.50 Hz."""
    frf = read_frf(shared_data / "southampton" / "frfs" / "Hammer.csv", kind="accelerance", input_name="hammer")
    assert frf.H.shape == (499, 3, 1) and frf.inputs == ("hammer",) and frf.units == "m/s^2/N"
    assert np.allclose(np.diff(frf.frequencies), 0.124875)
    assert np.all(np.isfinite(frf.H))
    assert np.all(np.abs(_band_peak(frf, 3.0, 10.0) - 6.5) <= 0.3)


def test_pyuff_meas_points(shared_data):
    """pyuff's ``meas_point_{1,2,3}.txt``: one complex column each, 1001 lines, 0-1000 Hz."""
    paths = [shared_data / "uff" / f"meas_point_{k}.txt" for k in (1, 2, 3)]
    frf = read_frf(paths, kind="accelerance")
    assert frf.H.shape == (1001, 3, 1)
    assert frf.outputs == ("meas_point_1", "meas_point_2", "meas_point_3")
    assert frf.frequencies[0] == 0.0 and frf.frequencies[-1] == 1000.0
    assert frf.kind == "accelerance" and np.all(np.isfinite(frf.H))
    assert frf.settings["frequency_axis"].startswith("assumed")
    first = complex(paths[0].read_text().splitlines()[0].strip())
    assert frf.H[0, 0, 0] == first
    by_glob = read_frf(str(shared_data / "uff" / "meas_point_*.txt"), df=0.5, output_names=["a", "b", "c"])
    assert by_glob.outputs == ("a", "b", "c") and by_glob.frequencies[-1] == 500.0
    assert np.array_equal(by_glob.H, frf.H)


@pytest.mark.parametrize("name, ftype", [
    ("Sample_UFF58_ascii.uff", "function type 1 (time response)"),
    ("Sample_UFF58b_bin.uff", "function type 1 (time response)"),
    ("MPSTD_Set001_2024_10_08.uff", "function type 1 (time response)"),
    ("sample_dataset58_psd.uff", "function type 9 (PSD)"),
])
def test_uff_without_frf_is_a_clear_error(shared_data, name, ftype):
    """pyuff's samples hold time data and a PSD, no FRF: the error names file and types."""
    with pytest.raises(LogFormatError, match="no UFF 58 FRF record") as e:
        read_frf(shared_data / "uff" / name)
    assert name in str(e.value) and ftype in str(e.value)


# --- text formats ------------------------------------------------------------------------

def test_csv_re_im_and_mag_phase_headers(tmp_path):
    f = np.arange(1, 6) * 0.5
    h1 = _sdof_frf(f, 1.2, 0.05)
    h2 = 2 * _sdof_frf(f, 2.1, 0.03)
    g = "{:.17g}".format
    p = tmp_path / "reim.csv"
    rows = (f"{g(x)}, {g(a.real)}, {g(a.imag)}, {g(b.real)}, {g(b.imag)}\n" for x, a, b in zip(f, h1, h2))
    p.write_text("f, re_a, im_a, re_b, im_b\n" + "".join(rows))
    frf = read_frf(p, kind="receptance")
    assert frf.outputs == ("a", "b") and frf.kind == "receptance" and frf.units == "m/N"
    assert np.array_equal(frf.frequencies, f) and np.allclose(frf.H[:, :, 0], np.c_[h1, h2], rtol=1e-15)

    p = tmp_path / "magph.txt"
    p.write_text("freq;mag_1;phase_1;mag_2_dB;phase_2\n" + "".join(
        f"{g(x)};{g(abs(a))};{g(np.degrees(np.angle(a)))};{g(20 * np.log10(abs(b)))};{g(np.degrees(np.angle(b)))}\n"
        for x, a, b in zip(f, h1, h2)))
    frf = read_frf(p)
    assert frf.outputs == ("1", "2") and frf.kind is None
    assert np.allclose(frf.H[:, :, 0], np.c_[h1, h2], rtol=1e-12)

    p = tmp_path / "complex_named.csv"
    p.write_text("Frequency [Hz],H11,H21\n" + "".join(f"{x},{a},{b}\n" for x, a, b in zip(f, h1, h2)))
    frf = read_frf(p)
    assert frf.outputs == ("H11", "H21") and np.allclose(frf.H[:, :, 0], np.c_[h1, h2], rtol=1e-15)


def test_garbage_csv_line_names_line_and_column(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("0.5+0j;1+1j;2+2j\n1.0+0j;1+1j;2+2j\n1.5+0j;oops;2+2j\n2.0+0j;1+1j;2+2j\n")
    with pytest.raises(LogFormatError, match=r"bad\.csv: line 3, column 2: cannot read 'oops'"):
        read_frf(p)
    p.write_text("0.5;1+1j;2+2j\n1.0;1+1j\n")
    with pytest.raises(LogFormatError, match=r"line 2: 2 columns"):
        read_frf(p)
    p.write_text("0.5+1j;1+1j\n1.0;1+1j\n")
    with pytest.raises(LogFormatError, match=r"line 1, column 1: the frequency must be real"):
        read_frf(p)
    p.write_text("1.0;1+1j\n0.5;1+1j\n")
    with pytest.raises(LogFormatError, match=r"line 2, column 1: frequency 0.5 Hz does not increase"):
        read_frf(p)
    p.write_text("f,re_1,phase_1\n1,2,3\n")
    with pytest.raises(LogFormatError, match=r"column 2 \('re_1'\)"):
        read_frf(p)
    with pytest.raises(LogFormatError, match="no such file"):
        read_frf(tmp_path / "absent.csv")
    with pytest.raises(LogFormatError, match="matches no file"):
        read_frf(str(tmp_path / "nothing_*.txt"))


def test_files_with_different_axes_do_not_combine(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("(1+1j)\n(2+2j)\n")
    b.write_text("(1+1j)\n(2+2j)\n(3+3j)\n")
    with pytest.raises(LogFormatError, match="b.txt: frequency axis"):
        read_frf([a, b])


# --- UFF 58 round trips --------------------------------------------------------------------

@pytest.mark.parametrize("binary", [False, True])
def test_uff58_round_trip(tmp_path, binary):
    frf = _synthetic_frf()
    p = write_frf_uff58(frf, tmp_path / "frf.uff", binary=binary)
    back = read_frf(p)
    assert back.outputs == frf.outputs and back.inputs == frf.inputs
    assert back.kind == "accelerance" and back.units == "m/s^2/N" and back.settings["binary"] == [int(binary)]
    assert np.allclose(back.frequencies, frf.frequencies, rtol=1e-6, atol=0)
    rel = np.abs(back.H - frf.H) / np.maximum(np.abs(frf.H), 1e-300)
    assert np.nanmax(rel[np.abs(frf.H) > 0]) < 1e-6 and np.all(back.H[frf.H == 0] == 0)
    assert np.allclose(back.coherence, frf.coherence, rtol=1e-6, atol=0)


def test_uff58_several_inputs_named_channels_and_no_coherence(tmp_path):
    """Names that are not node DOFs travel in ID lines 1 (output) and 4 (input); the multiple
    coherence of several inputs is not written, so it reads back NaN."""
    frf = _synthetic_frf(outputs=("/imu/s01.linear_acceleration.x", "floor 2"), inputs=("shaker", "7+Y"),
                         n=64, df=1 / 3, coherence=True)
    frf = FRF(frequencies=frf.frequencies, H=frf.H, coherence=frf.coherence, inputs=frf.inputs, outputs=frf.outputs,
              estimator="H1", kind=None, units="", settings={})
    back = read_frf(write_frf_uff58(frf, tmp_path / "m.unv"))
    assert back.outputs == frf.outputs and back.inputs == frf.inputs and back.kind is None
    assert np.allclose(back.H, frf.H, rtol=1e-9) and np.all(np.isnan(back.coherence))
    # the abscissa keeps the format's 6 significant digits
    assert np.allclose(back.frequencies, frf.frequencies, rtol=2e-5)


def test_uff58_frf_among_other_records(tmp_path):
    """Time records before an FRF are skipped; a time-only file names what it holds."""
    import pyuff

    p = tmp_path / "mixed.uff"
    t = np.arange(100) / 100.0
    time_rec = pyuff.prepare_58(func_type=1, rsp_node=1, rsp_dir=3, ref_node=0, ref_dir=0,
                                data=np.sin(t), x=t, id1="time", abscissa_spacing=1,
                                abscissa_spec_data_type=17, ordinate_spec_data_type=12, orddenom_spec_data_type=0)
    frf = _synthetic_frf(outputs=("1+Z",), n=50)
    write_frf_uff58(frf, tmp_path / "frf.uff")
    pyuff.UFF(str(p)).write_sets([time_rec], mode="add")
    with pytest.raises(LogFormatError, match=r"mixed\.uff: no UFF 58 FRF record.*function type 1 \(time response\)"):
        read_frf(p)
    p.write_bytes(p.read_bytes() + (tmp_path / "frf.uff").read_bytes())
    back = read_frf(p, kind="mobility")
    assert back.outputs == ("1+Z",) and back.kind == "mobility" and back.units == "m/s/N"
    assert np.allclose(back.H, frf.H, rtol=1e-9)


# --- UFF 55 modes, UFF 15/2411 geometry --------------------------------------------------

def test_uff55_modes_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    shapes = rng.standard_normal((3, 4)) + 1j * rng.standard_normal((3, 4))
    mm = ModalModel(natural_frequencies=[6.5, 17.47, 26.5], damping_ratios=[0.012, 0.004, np.nan], shapes=shapes,
                    points=["1+Z", "2+Z", "3+Z", "3+X"], method="lscf")
    back = read_modes_uff55(write_modes_uff55(mm, tmp_path / "modes.uff"))
    assert back.method == "lscf" and back.points == ("1+Z", "2+Z", "3+X", "3+Z")
    assert np.allclose(back.natural_frequencies, mm.natural_frequencies, rtol=1e-5)
    assert np.allclose(back.damping_ratios[:2], mm.damping_ratios[:2], rtol=1e-4) and np.isnan(back.damping_ratios[2])
    order = [mm.points.index(p) for p in back.points]
    assert np.allclose(back.shapes, mm.shapes[:, order], rtol=1e-5, atol=1e-5 * np.abs(shapes).max())
    assert list(back.extra["mode_numbers"]) == [1, 2, 3] and list(back.extra["analysis_types"]) == [3, 3, 3]


def test_uff55_named_points_and_normal_modes(tmp_path):
    """Points that are not node DOFs are placed by node_ids/directions; pyuff's own normal-mode
    records (analysis type 2) read with their frequency and viscous damping ratio."""
    import pyuff

    mm = ModalModel(natural_frequencies=[10.0], damping_ratios=[0.03], shapes=[[1.0, -0.5j]], points=["a", "b"],
                    method="fdd")
    back = read_modes_uff55(write_modes_uff55(mm, tmp_path / "m.uff", node_ids=[5, 9], directions=["-y", 1]))
    assert back.points == ("5+Y", "9+X") and np.allclose(back.shapes, [[-1.0, -0.5j]], atol=1e-6)
    with pytest.raises(ValueError, match="share node"):
        write_modes_uff55(mm, tmp_path / "x.uff", node_ids=[1, 1])

    p = tmp_path / "normal.uff"
    ds = pyuff.prepare_55(model_type=1, analysis_type=2, data_ch=2, spec_data_type=8, data_type=2,
                          r1=np.zeros(2), r2=np.zeros(2), r3=np.array([1.0, -0.5]), n_data_per_node=3,
                          node_nums=np.array([1, 2]), load_case=1, mode_n=1, modal_m=0, freq=4.5,
                          modal_damp_vis=0.01, modal_damp_his=0.0)
    pyuff.UFF(str(p)).write_sets([ds], mode="add")
    nm = read_modes_uff55(p)
    assert nm.points == ("1+Z", "2+Z") and nm.natural_frequencies[0] == 4.5 and nm.damping_ratios[0] == 0.01
    assert np.allclose(nm.shapes, [[1.0, -0.5]]) and nm.method == "uff55"
    with pytest.raises(LogFormatError, match="no UFF 55 mode record"):
        read_modes_uff55(write_frf_uff58(_synthetic_frf(n=8), tmp_path / "f.uff"))


def test_geometry_round_trip(tmp_path):
    ids = np.array([1, 2, 3, 10])
    xyz = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.5], [0.3, 0.45, 1.0], [-1.25e-3, 2.5, 3.75]])
    rid, rxyz = read_geometry(write_geometry_uff15(tmp_path / "geo.uff", ids, xyz))
    assert np.array_equal(rid, ids) and np.allclose(rxyz, xyz, rtol=1e-5, atol=1e-12)
    with pytest.raises(ValueError, match="unique"):
        write_geometry_uff15(tmp_path / "g.uff", [1, 1], np.zeros((2, 3)))


def test_geometry_2411_in_millimetres(tmp_path):
    """Double-precision nodes (2411) after a units record in mm (length factor 1000)."""
    import pyuff

    p = tmp_path / "mm.unv"
    units = pyuff.prepare_164(units_code=5, units_description="mm (milli newton)", temp_mode=2,
                              length=1000.0, force=1000.0, temp=1.0, temp_offset=273.15)
    nodes = pyuff.prepare_2411(node_nums=np.array([4, 7]), def_cs=np.zeros(2, int), disp_cs=np.zeros(2, int),
                               color=np.ones(2, int), x=np.array([100.0, 250.5]), y=np.array([0.0, 1.0]),
                               z=np.array([1234.5678, 0.0]))
    pyuff.UFF(str(p)).write_sets([units, nodes], mode="add")
    ids, xyz = read_geometry(p)
    assert ids.tolist() == [4, 7]
    assert np.allclose(xyz, [[0.1, 0.0, 1.2345678], [0.2505, 0.001, 0.0]], rtol=1e-14)
    with pytest.raises(LogFormatError, match=r"no node record \(dataset 15 or 2411\).*dataset 58"):
        read_geometry(write_frf_uff58(_synthetic_frf(n=8), tmp_path / "f.uff"))


def test_uff_geometry_places_dof_named_channels(tmp_path):
    """`--coords geometry.uff`: channels named like UFF DOFs sit at their nodes, along their axes."""
    from vibroscope.io import write_geometry_uff15
    from vibroscope.io.coords import read_coords

    geo = tmp_path / "geo.uff"
    write_geometry_uff15(geo, [3, 7], np.array([[0.0, 0.0, 1.5], [0.2, 0.0, 3.0]]))
    sc = read_coords(geo, ["7+X", "3-Z"])
    np.testing.assert_allclose(sc.xyz, [[0.2, 0.0, 3.0], [0.0, 0.0, 1.5]], atol=1e-6)
    np.testing.assert_allclose(sc.directions, [[1, 0, 0], [0, 0, -1]])
    with pytest.raises(Exception, match="not a DOF"):
        read_coords(geo, ["/imu/a.linear_acceleration.x"])


def test_non_finite_lines_are_reported(tmp_path):
    """NaN lines in one output and one Inf: a warning per output naming the count, the frequencies and
    the rows (before: accepted silently), also in ``settings["warnings"]``; the finite lines are read
    as they are."""
    f = np.arange(1, 41) * 0.5
    h = _sdof_frf(f, 10.0, 0.05)
    cols = [h.astype(complex), 2 * h.astype(complex)]
    cols[0][10:15] = np.nan
    cols[1][30] = np.inf
    p = tmp_path / "holes.csv"
    p.write_text("f,a,b\n" + "".join(f"{x},{a},{b}\n" for x, a, b in zip(f, *cols)))
    with pytest.warns(UserWarning) as rec:
        frf = read_frf(p)
    msgs = [str(w.message) for w in rec]
    assert len(msgs) == 2 and "output 'a': 5 of 40 values not finite" in msgs[0] and "5.5–7.5 Hz (rows 10–14)" in msgs[0]
    assert "output 'b': 1 of 40" in msgs[1] and "15.5–15.5 Hz (rows 30–30)" in msgs[1]
    assert frf.settings["warnings"] == [m.split(": ", 1)[1] for m in msgs]
    assert np.array_equal(frf.H[:10, 0, 0], cols[0][:10])
