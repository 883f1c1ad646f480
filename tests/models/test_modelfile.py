"""Model files: the fixed TOML schema, round trips, and errors that name key and line."""

import numpy as np
import pytest

from vibroscope.errors import ModelFileError
from vibroscope.models.boucwen_benchmark import boucwen_benchmark_model
from vibroscope.models.elements import Backlash, BoucWen, CubicSpring, Friction, MRDamper
from vibroscope.models.lumped import LumpedModel, demo_model
from vibroscope.models.modelfile import TransferFunctionModel, dump_model, dumps_model, load_model, loads_model
from vibroscope.models.simulate import simulate

GOOD = """\
kind = "lumped"
[[dof]]
name = "m1"
mass = 2.0                      # kg
[[dof]]
name = "m2"
mass = 1.0
[[element]]
type = "spring"                 # spring | damper | ...
between = ["m1", "ground"]
k = 5.0e4                       # N/m
[[element]]
type = "spring"
between = ["m2", "m1"]
k = 2.0e4
[[element]]
type = "damper"
between = ["m2", "m1"]
c = 3.0
[[element]]
type = "cubic_spring"
between = ["m1", "ground"]
k3 = 1.0e9
[[input]]
channel = "/actuator/force_cmd.wrench.force.x"   # message path in the log
dof = "m1"
quantity = "force"
saturation = 50.0
[[output]]
channel = "/imu/m1.linear_acceleration.x"
dof = "m1"
quantity = "acceleration"
[[output]]
channel = "/imu/m2.linear_acceleration.x"
dof = "m2"
quantity = "acceleration"
"""


def write(tmp_path, text, name="model.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_load_good_file(tmp_path):
    m = load_model(write(tmp_path, GOOD))
    assert isinstance(m, LumpedModel)
    assert m.dof_names == ("m1", "m2")
    np.testing.assert_array_equal(m.K, [[7e4, -2e4], [-2e4, 2e4]])
    np.testing.assert_array_equal(m.C, [[3.0, -3.0], [-3.0, 3.0]])
    assert isinstance(m.elements[3], CubicSpring) and m.elements[3].k3 == 1e9
    assert m.inputs[0].saturation == 50.0
    assert m.input_channels() == ["/actuator/force_cmd.wrench.force.x"]
    assert m.output_channels() == ["/imu/m1.linear_acceleration.x", "/imu/m2.linear_acceleration.x"]


@pytest.mark.parametrize(
    "model",
    [
        demo_model(),
        boucwen_benchmark_model(),
        LumpedModel.chain(
            [1.0, 2.0],
            [1e4, 2e4],
            [1.0, 0.0],
            nonlinear=(
                Backlash(("m1", "m2"), k=1e5, gap=1e-3),
                Friction(("m2", "ground"), force_=2.0, v_eps=0.01),
                MRDamper(("m1", "ground"), current=0.5),
            ),
        ),
        LumpedModel.chain([1.0], [1e4], [1.0], nonlinear=(CubicSpring(("m1", "ground"), k3=2e9, k5=-3e14),)),
    ],
)
def test_roundtrip(tmp_path, model):
    p = tmp_path / "m.toml"
    dump_model(model, p)
    assert load_model(p) == model


def test_transfer_function(tmp_path):
    text = """kind = "transfer_function"
num = [1.0]
den = [1.0, 2.0, 100.0]
[[input]]
channel = "/cmd.wrench.force.x"
quantity = "force"
[[output]]
channel = "/imu/a.linear_acceleration.x"
quantity = "displacement"
"""
    m = load_model(write(tmp_path, text))
    assert isinstance(m, TransferFunctionModel)
    f = np.array([0.5, 1.6, 3.0])
    s = 2j * np.pi * f
    np.testing.assert_allclose(m.frf(f)[:, 0, 0], 1 / (s**2 + 2 * s + 100))
    # time simulation of the TF: steady-state step = num/den at s = 0
    sig = simulate(m, np.ones(5000), 100.0)
    assert sig.data[1, -1] == pytest.approx(0.01, rel=1e-4)
    assert sig.channels == ("/cmd.wrench.force.x", "/imu/a.linear_acceleration.x")
    p = tmp_path / "tf2.toml"
    dump_model(m, p)
    assert load_model(p) == m


def _err(tmp_path, text):
    with pytest.raises(ModelFileError) as exc:
        load_model(write(tmp_path, text))
    return str(exc.value)


def test_unknown_key_names_key_and_line(tmp_path):
    text = GOOD.replace('k = 2.0e4\n', 'k = 2.0e4\nstiffnes = 3.0\n')
    msg = _err(tmp_path, text)
    line = text.splitlines().index("stiffnes = 3.0") + 1
    assert f"model.toml:{line}:" in msg and "'stiffnes'" in msg


def test_signed_spring_takes_a_negative_stiffness_that_a_spring_refuses(tmp_path):
    text = GOOD.replace('type = "spring"\nbetween = ["m2", "m1"]\nk = 2.0e4',
                        'type = "spring"\nbetween = ["m2", "m1"]\nk = 2.0e4\n[[element]]\n'
                        'type = "signed_spring"\nbetween = ["m2", "m1"]\nk = -5.0e3')
    m = load_model(write(tmp_path, text))
    base = load_model(write(tmp_path, GOOD, "base.toml"))
    # the two springs of m2-m1 add to 1.5e4 N/m: K is the base's with 5e3 N/m taken out
    dK = m.K - base.K
    np.testing.assert_allclose(dK, -5e3 * np.array([[1.0, -1.0], [-1.0, 1.0]]))
    assert loads_model(dumps_model(m)) == m
    msg = _err(tmp_path, text.replace('type = "signed_spring"', 'type = "spring"'))
    assert "'k'" in msg and ">= 0" in msg


def test_negative_mass_names_key_and_line(tmp_path):
    text = GOOD.replace("mass = 1.0", "mass = -1.0")
    msg = _err(tmp_path, text)
    line = text.splitlines().index("mass = -1.0") + 1
    assert f":{line}:" in msg and "'mass'" in msg and "[[dof]] #2" in msg


def test_negative_stiffness_and_missing_dof(tmp_path):
    text = GOOD.replace("k = 2.0e4", "k = -2.0e4")
    msg = _err(tmp_path, text)
    assert f":{text.splitlines().index('k = -2.0e4') + 1}:" in msg and "'k'" in msg
    text = GOOD.replace('between = ["m2", "m1"]\nk', 'between = ["m3", "m1"]\nk')
    msg = _err(tmp_path, text)
    line = text.splitlines().index('between = ["m3", "m1"]') + 1
    assert f":{line}:" in msg and "'m3'" in msg
    text = GOOD.replace('dof = "m2"', 'dof = "m9"')
    msg = _err(tmp_path, text)
    line = text.splitlines().index('dof = "m9"') + 1
    assert f":{line}:" in msg and "'dof'" in msg


@pytest.mark.parametrize(
    "old, new, key",
    [
        ('kind = "lumped"', 'kind = "fem"', "'kind'"),
        ('type = "damper"', 'type = "dashpot"', "'type'"),
        ('quantity = "acceleration"\n[[output]]', 'quantity = "jerk"\n[[output]]', "'quantity'"),
        ("saturation = 50.0", "saturation = -5.0", "'saturation'"),
        ("k3 = 1.0e9", "k3 = 1.0e9\nk3 = 2.0", "invalid TOML"),
        ('kind = "lumped"', 'kind = "lumped"\nunits = "SI"', "'units'"),
        ("k3 = 1.0e9", "", "'k3'"),
    ],
)
def test_more_errors(tmp_path, old, new, key):
    text = GOOD.replace(old, new, 1)
    msg = _err(tmp_path, text)
    assert key in msg and "model.toml:" in msg


def test_bouc_wen_and_mr_params(tmp_path):
    text = GOOD.replace(
        'type = "cubic_spring"\nbetween = ["m1", "ground"]\nk3 = 1.0e9',
        'type = "bouc_wen"\nbetween = ["m1", "ground"]\nalpha = 5e4\nbeta = 1e3\ngamma = 0.8\ndelta = -1.1',
    ).replace('[[input]]', '[[element]]\ntype = "mr_damper"\nbetween = ["m2", "ground"]\ni = 1.5\n[[input]]')
    m = load_model(write(tmp_path, text))
    assert isinstance(m.elements[3], BoucWen) and m.elements[3].nu == 1.0
    assert isinstance(m.elements[4], MRDamper) and m.elements[4].current == 1.5


def test_loads_model_parses_text_and_names_its_path(tmp_path):
    """The text parser behind load_model: same model, and errors name the path it is given."""
    assert loads_model(GOOD) == load_model(write(tmp_path, GOOD))
    with pytest.raises(ModelFileError, match=r"^<string>:\d+:.*'mass'"):
        loads_model(GOOD.replace("mass = 1.0", "mass = -1.0"))
    with pytest.raises(ModelFileError, match=r"^rig\.toml:\d+:.*'kind'"):
        loads_model(GOOD.replace('kind = "lumped"', 'kind = "fem"'), path="rig.toml")


def test_missing_file(tmp_path):
    with pytest.raises(ModelFileError, match="cannot read"):
        load_model(tmp_path / "nope.toml")


# --- issue 8: model files are data; every error names file, dotted key and line ------------------------


def _line_of(text, needle):
    return text.split("\n").index(needle) + 1


@pytest.mark.parametrize(
    "old, new, needle, dotted",
    [
        # unknown key
        ("k = 2.0e4\n", "k = 2.0e4\nstiffnes = 3.0\n", "stiffnes = 3.0", "element[1].stiffnes"),
        # non-physical value
        ("mass = 1.0", "mass = -1.0", "mass = -1.0", "dof[1].mass"),
        # wrong type
        ("k3 = 1.0e9", 'k3 = "stiff"', 'k3 = "stiff"', "element[3].k3"),
        ("saturation = 50.0", "saturation = nan", "saturation = nan", "input[0].saturation"),
        # missing DOF
        ('dof = "m2"', 'dof = "m9"', 'dof = "m9"', "output[1].dof"),
        # a huge integer (no float holds it): an error, not an OverflowError
        ("mass = 1.0", "mass = 1" + "0" * 400, "mass = 1" + "0" * 400, "dof[1].mass"),
        ('kind = "lumped"', 'kind = "fem"', 'kind = "fem"', "kind"),
    ],
)
def test_semantic_errors_name_file_dotted_key_and_line(tmp_path, old, new, needle, dotted):
    text = GOOD.replace(old, new, 1)
    assert text != GOOD
    msg = _err(tmp_path, text)
    n = _line_of(text, needle)
    assert msg.startswith(f"{tmp_path / 'model.toml'}:{n}:"), msg
    assert f"({dotted}, line {n})" in msg, msg


def test_missing_key_names_dotted_key_and_block_line(tmp_path):
    text = GOOD.replace('between = ["m2", "m1"]\nc = 3.0', 'c = 3.0')
    msg = _err(tmp_path, text)
    # the third [[element]] block, whose header is on this line
    n = [i for i, ln in enumerate(text.split("\n"), 1) if ln == "[[element]]"][2]
    assert "missing required key 'between'" in msg and f"(element[2].between, line {n})" in msg, msg
    msg = _err(tmp_path, GOOD.replace('kind = "lumped"\n', ""))
    assert "(kind, line 1)" in msg


@pytest.mark.parametrize(
    "old, new, line_of, key",
    [
        ("mass = 1.0", "mass = 1.0.0", "mass = 1.0.0", "mass"),  # a bad number
        ('name = "m2"', 'name = "m2', 'name = "m2', "name"),  # unterminated string
        ("k3 = 1.0e9", "k3 = 1.0e9\nk3 = 2.0", "k3 = 2.0", "k3"),  # a key given twice
    ],
)
def test_syntax_errors_name_line_and_key(tmp_path, old, new, line_of, key):
    text = GOOD.replace(old, new, 1)
    msg = _err(tmp_path, text)
    n = _line_of(text, line_of)
    assert msg.startswith(f"{tmp_path / 'model.toml'}:{n}: line {n} key {key!r}: invalid TOML"), msg


def test_line_numbers_count_lf_only(tmp_path):
    """A LINE SEPARATOR (U+2028) in a comment is no line break for TOML: the line reported is tomllib's."""
    text = GOOD.replace("# kg", "# kg \u2028 per DOF").replace("mass = 1.0", "mass = -1.0")
    msg = _err(tmp_path, text)
    n = _line_of(text, "mass = -1.0")
    assert f"(dof[1].mass, line {n})" in msg and msg.startswith(f"{tmp_path / 'model.toml'}:{n}:")


def test_binary_and_empty_files(tmp_path):
    p = tmp_path / "bin.toml"
    p.write_bytes(b'kind = "lumped"\n\xff\xfe\x00garbage')
    with pytest.raises(ModelFileError, match=r"bin\.toml:2: line 2: not a text \(UTF-8\) model file"):
        load_model(p)
    p.write_bytes(b"")
    with pytest.raises(ModelFileError, match=r"bin\.toml:1: .*missing required key 'kind'"):
        load_model(p)


def test_no_code_is_executed_or_unpickled():
    """Model files are data: the parser has no eval, exec, pickle or import machinery."""
    import inspect
    import re

    import vibroscope.models.modelfile as mf

    src = inspect.getsource(mf)
    for word in ("eval(", "exec(", "pickle", "__import__", "importlib", "compile(", "marshal", "yaml"):
        assert not re.search(rf"(?<![\w.]){re.escape(word)}", src), word  # re.compile( is fine
    assert re.search(r"^import tomllib$", src, re.M)
