"""Model files (TOML): lumped models, SISO transfer functions and pole-residue (modal) models.

Schema (fixed)::

    kind = "lumped"
    [[dof]]
    name = "m1"
    mass = 2.0                      # kg
    [[element]]
    type = "spring"                 # spring | signed_spring | damper | signed_damper | signed_mass | cubic_spring | backlash | friction | bouc_wen | mr_damper
    between = ["m1", "ground"]      # two DOF names, or a DOF and "ground"
    k = 5.0e4                       # N/m
    [[input]]
    channel = "/actuator/force_cmd.wrench.force.x"
    dof = "m1"
    quantity = "force"              # N; optional: saturation = N, delay = s, offset = N
                                    # saturation_law = "clip" (default) | "tanh": saturation tanh(u / saturation)
    [[output]]
    channel = "/imu/m1.linear_acceleration.x"
    dof = "m1"
    quantity = "acceleration"       # acceleration | velocity | displacement
    [[controller]]                  # optional: a discrete loop around the model
    name = "position"
    law = "cascade"                 # P | PD | PID | PD2 | PI_PDT1 | cascade
    gains = {kp = 160.18, kv = 243.45}   # per law (below); u = the command's unit
    rate_hz = 1000.0                # Hz; zero-order hold on the command (several controllers:
                                    # each rate the fastest divided by a whole number)
    dof = "m1"                      # the measured DOF
    drives = "/actuator/force_cmd.wrench.force.x"   # the [[input]] driven: channel or index
    reference = "/emps/qg.x"        # optional: logged position reference (m); else 0
    measures = ["position"]         # optional: + "velocity", "acceleration" sampled states
    velocity_filter = {type = "fir", taps = [0.5, 0.5]}   # optional, before differencing
    gain = 35.15                    # N per command unit (actuator / drive gain)
    saturation = 10.0               # optional: command limit, command unit
    output_channel = "/emps/vir.x"  # optional: logged command, compared as an output
    output_unit = "V"               # optional, default "1"
    feedforward = "/emps/pulses.x"  # optional: logged channel added to the command

Controller laws and gains (:data:`vibroscope.models.controller.LAWS`, difference equations
in :mod:`vibroscope.models.controller`): P ``kp`` (u/m); PD ``kp``, ``kd`` (u s/m); PID
``kp``, ``ki`` (u/(m s)), ``kd``; PD2 ``kp``, ``ka`` (u s^2/m), ``kd`` optional; PI_PDT1
``kp``, ``ki``, ``t1`` (s), ``td`` (s) optional; cascade ``kp`` (1/s), ``kv`` (u s/m): the
command ``kp kv (r - q) - kv qdot``. A model with controllers is simulated in closed loop:
its logged rows are the references, then the feed-forwards, then the inputs no controller
drives.

Element parameters: spring ``k`` (>= 0); signed_spring ``k`` (any sign: a stiffness taken out of
a connection that has no spring of its own, as in a modal-coordinates model); damper ``c``;
signed_damper ``c`` (any sign: a damping change where there is no damper of its own); signed_mass
``m`` (kg, any sign: a point mass added to or taken out of a measured point of a modal-coordinates
model, to ground; between two ends an inerter); cubic_spring ``k3`` (``k`` and the quintic ``k5`` optional);
backlash ``k``, ``gap``; friction ``force`` (``v_eps`` optional; ``force_neg``, the sliding
force for negative velocity, optional, default ``force``); bouc_wen ``alpha``, ``beta``,
``gamma``, ``delta`` (``nu`` optional, default 1); mr_damper ``i`` (current, A) and optionally
the Spencer et al. (1997) coefficients (see :class:`vibroscope.models.elements.MRDamper`).

A lumped model in modal coordinates
(:class:`vibroscope.models.modal_coordinates.ModalCoordinatesModel`, what the gap diagnosis
makes of a modal model) adds measured points, each a combination of the DOFs
``x_point = sum_r shape[r] x_r`` over the first DOFs (further DOFs do not move it); elements,
inputs and outputs may name a point::

    [[point]]
    name = "out1"
    shape = [0.21, -0.48, 0.63]     # 1/sqrt(kg) per modal DOF, in [[dof]] order

``kind = "transfer_function"``: ``num`` and ``den`` (coefficients of s, highest power
first), one ``[[input]]`` and one ``[[output]]`` (``channel``, ``quantity``).

``kind = "modal"``: a pole-residue model (:class:`vibroscope.models.modal_model.PoleResidueModel`),
e.g. an identified LSCF + LSFD model::

    kind = "modal"
    name = "frame, identified by LSCF"
    [[input]]
    channel = "/actuator/force.wrench.force.x"
    quantity = "force"                  # optional: saturation = N, delay = s, offset = N
    [[output]]
    channel = "/imu/m1.linear_acceleration.x"
    quantity = "acceleration"           # the quantity the residues refer to
    [[mode]]
    frequency_hz = 18.39                # > 0, undamped natural frequency
    damping_ratio = 0.0102              # 0 <= zeta < 1
    residues = [[[1.2e-3, -4.5e-2]]]    # [re, im] per (output, input): (n_outputs, n_inputs, 2)
    [residual]                          # optional table; both keys optional
    lower = [[[0.0, 0.0]]]              # (n_outputs, n_inputs, 2), multiplies (jw)^(p-2)
    upper = [[[0.0, 0.0]]]              # (n_outputs, n_inputs, 2), multiplies (jw)^p

with ``H_oi(jw) = sum_r [R_r,oi / (jw - lambda_r) + conj(R_r,oi) / (jw - conj(lambda_r))]
+ LR_oi (jw)^(p-2) + UR_oi (jw)^p``, ``lambda_r = -zeta_r w_r + j w_r sqrt(1 - zeta_r^2)``,
``w_r = 2 pi f_r``, and ``p`` = 0, 1, 2 for displacement, velocity, acceleration outputs.
Residue rows follow the ``[[output]]`` tables, columns the ``[[input]]`` tables, in file
order; ``[[input]]``/``[[output]]`` may carry a free ``dof`` label. At least one
``[[mode]]``.

Every fault raises :class:`vibroscope.errors.ModelFileError` naming the file, the line and
the key.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vibroscope.errors import ModelFileError
from vibroscope.models.controller import LAWS, MEASURES, Controller
from vibroscope.models.elements import ELEMENT_TYPES, GROUND, Element, make_element
from vibroscope.models.lumped import QUANTITIES, Dof, Input, LumpedModel, Output
from vibroscope.models.modal_model import PoleResidueModel

__all__ = ["TransferFunctionModel", "load_model", "dump_model", "loads_model", "dumps_model"]

#: the ``kind`` values a model file may have
KINDS = ("lumped", "transfer_function", "modal")
#: tables written ``[name]`` (one), not ``[[name]]`` (array of tables)
_SINGLE_TABLES = {"residual"}


@dataclass(frozen=True)
class TransferFunctionModel:
    """A SISO transfer function ``H(s) = num(s) / den(s)`` between two log channels.

    Parameters
    ----------
    num, den : tuple of float
        Polynomial coefficients in s, highest power first (proper: ``len(num) <= len(den)``).
    input : Input
        Input channel (``dof`` is a label, ``quantity`` "force").
    output : Output
        Output channel and quantity.
    name : str
        Free label.
    """

    num: tuple[float, ...]
    den: tuple[float, ...]
    input: Input
    output: Output
    name: str = ""

    def __post_init__(self) -> None:
        num = np.trim_zeros(np.atleast_1d(np.asarray(self.num, float)), "f")
        den = np.trim_zeros(np.atleast_1d(np.asarray(self.den, float)), "f")
        if den.size == 0:
            raise ValueError("den must have a nonzero coefficient")
        if num.size > den.size:
            raise ValueError(f"improper transfer function: {len(num)=} > {len(den)=}")
        if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))):
            raise ValueError("num and den must be finite")
        object.__setattr__(self, "num", tuple(num.tolist()) or (0.0,))
        object.__setattr__(self, "den", tuple(den.tolist()))

    # the interface simulate() uses
    @property
    def inputs(self) -> tuple[Input, ...]:
        return (self.input,)

    @property
    def outputs(self) -> tuple[Output, ...]:
        return (self.output,)

    @property
    def elements(self) -> tuple:
        return ()

    @property
    def is_linear(self) -> bool:
        return self.input.saturation is None

    def input_channels(self) -> list[str]:
        """The input's channel name, in a one-item list (default ``/input.x``)."""
        return [self.input.channel or "/input.x"]

    def output_channels(self) -> list[str]:
        """The output's channel name, in a one-item list (default ``/output.x``)."""
        return [self.output.channel or "/output.x"]

    def state_matrices(self):
        """Controllable canonical state space ``(A, B, C, D)`` of ``num/den``."""
        from scipy import signal

        return signal.tf2ss(self.num, self.den)

    def tf(self):
        """The :class:`control.TransferFunction`."""
        import control

        return control.tf(list(self.num), list(self.den))

    def frf(self, frequencies) -> np.ndarray:
        """``H(j 2 pi f)``, shape (n_f, 1, 1), times the input delay factor.

        Parameters
        ----------
        frequencies : float or array_like, shape (n_f,)
            Frequencies in Hz.

        Returns
        -------
        ndarray of complex, shape (n_f, 1, 1)
            ``num(s) / den(s) * exp(-s delay)`` at ``s = j 2 pi f``, with the input's
            ``delay`` in s; in the output unit per input unit.
        """
        s = 2j * np.pi * np.atleast_1d(np.asarray(frequencies, float))
        H = np.polyval(self.num, s) / np.polyval(self.den, s) * np.exp(-s * self.input.delay)
        return H[:, None, None]


# ---------------------------------------------------------------------------------------------
# locating keys in the text
# ---------------------------------------------------------------------------------------------
_HEADER = re.compile(r"^\s*\[\[?\s*([A-Za-z0-9_.\-]+)\s*\]\]?")


def _locate(text: str, table: str | None, index: int, key: str | None) -> int:
    """1-based line of `key` in the `index`-th ``[[table]]`` block (``table=None``: top level);
    the block's header line if the key is not written there."""
    counts: dict[str, int] = {}
    current, cur_idx = None, 0
    header_line = 1
    for lineno, line in enumerate(text.split("\n"), 1):  # TOML lines end at LF only (as tomllib counts)
        m = _HEADER.match(line)
        if m and not line.strip().startswith("#"):
            current = m.group(1)
            cur_idx = counts.get(current, 0)
            counts[current] = cur_idx + 1
            if current == table and cur_idx == index:
                header_line = lineno
            continue
        if current == table and (table is None or cur_idx == index) and key is not None:
            if re.match(rf"^\s*[\"']?{re.escape(key)}[\"']?\s*=", line):
                return lineno
    return header_line


def _dotted(table: str | None, index: int, key: str | None) -> str:
    """The dotted path of a key as the parsed document holds it: ``element[2].k`` (0-based
    index into the ``[[element]]`` array), ``residual.lower``, ``kind``."""
    if table is None:
        return key or ""
    head = table if table in _SINGLE_TABLES else f"{table}[{index}]"
    return f"{head}.{key}" if key else head


class _Ctx:
    def __init__(self, path: str, text: str):
        self.path, self.text = path, text

    def error(self, msg: str, table: str | None = None, index: int = 0, key: str | None = None,
              missing: str | None = None) -> ModelFileError:
        """``path:N: <block> key 'k' (element[2].k, line N): msg``; `missing` names a key that
        is absent (the line is then the block's header)."""
        line = _locate(self.text, table, index, key)
        if table in _SINGLE_TABLES:
            where = f"[{table}]"
        else:
            where = f"[[{table}]] #{index + 1}" if table else "top level"
        name = key or missing
        keytxt = f" key {name!r}" if name else ""
        dotted = _dotted(table, index, name)
        loc = f"{dotted}, line {line}" if dotted else f"line {line}"
        return ModelFileError(f"{self.path}:{line}: {where}{keytxt} ({loc}): {msg}")


def _number(ctx, tbl, table, i, key, *, positive=False, nonneg=False, required=True, default=None):
    if key not in tbl:
        if required:
            raise ctx.error(f"missing required key {key!r}", table, i, None, missing=key)
        return default
    v = tbl[key]
    ok = not isinstance(v, bool) and isinstance(v, (int, float))
    if ok and isinstance(v, int):
        ok = abs(v) <= 2**1023  # a huge TOML integer does not fit a float
    if not ok or not math.isfinite(v):
        raise ctx.error(f"{key}={_short(v)} must be a finite number", table, i, key)
    if positive and v <= 0:
        raise ctx.error(f"{key}={v!r} must be > 0", table, i, key)
    if nonneg and v < 0:
        raise ctx.error(f"{key}={v!r} must be >= 0", table, i, key)
    return float(v)


def _short(v, n: int = 60) -> str:
    """``repr(v)``, cut to `n` characters (a fuzzed value can be huge)."""
    r = repr(v) if not isinstance(v, int) or abs(v) < 10**40 else f"<integer of {len(str(abs(v)))} digits>"
    return r if len(r) <= n else r[: n - 3] + "..."


def _string(ctx, tbl, table, i, key, required=True, default=None):
    if key not in tbl:
        if required:
            raise ctx.error(f"missing required key {key!r}", table, i, None, missing=key)
        return default
    v = tbl[key]
    if not isinstance(v, str) or not v:
        raise ctx.error(f"{key}={_short(v)} must be a non-empty string", table, i, key)
    return v


def _unknown(ctx, tbl, table, i, allowed):
    for key in tbl:
        if key not in allowed:
            raise ctx.error(f"unknown key {_short(key)}; allowed: {sorted(allowed)}", table, i, key)


def _tables(ctx, doc, table):
    v = doc.get(table, [])
    if not isinstance(v, list) or not all(isinstance(t, dict) for t in v):
        raise ctx.error(f"{table!r} must be an array of tables [[{table}]]", None, 0, table)
    return v


_NONNEG = {"k", "c", "gap", "force", "force_neg", "k0", "k1"}
#: element types whose parameters may take either sign
_SIGNED = frozenset({"signed_spring", "signed_damper", "signed_mass"})
_POSITIVE = {"v_eps", "nu", "n"}


def _parse_io(ctx, doc, dof_names):
    inputs, outputs = [], []
    for i, t in enumerate(_tables(ctx, doc, "input")):
        _unknown(ctx, t, "input", i, {"channel", "dof", "quantity", "saturation", "saturation_law", "delay", "offset"})
        ch = _string(ctx, t, "input", i, "channel")
        dof = _string(ctx, t, "input", i, "dof", required=dof_names is not None, default="u")
        if dof_names is not None and dof not in dof_names:
            raise ctx.error(f"unknown DOF {dof!r}; DOFs are {sorted(dof_names)}", "input", i, "dof")
        q = _string(ctx, t, "input", i, "quantity", required=False, default="force")
        if q != "force":
            raise ctx.error(f"quantity={q!r} must be 'force'", "input", i, "quantity")
        sat = _number(ctx, t, "input", i, "saturation", positive=True, required=False)
        law = _string(ctx, t, "input", i, "saturation_law", required=False, default="clip")
        if law not in ("clip", "tanh"):
            raise ctx.error(f"saturation_law={law!r} must be 'clip' or 'tanh'", "input", i, "saturation_law")
        delay = _number(ctx, t, "input", i, "delay", nonneg=True, required=False, default=0.0)
        offset = _number(ctx, t, "input", i, "offset", required=False, default=0.0)
        inputs.append(Input(dof=dof, quantity=q, channel=ch, saturation=sat, delay=delay, offset=offset,
                            saturation_law=law))
    for i, t in enumerate(_tables(ctx, doc, "output")):
        _unknown(ctx, t, "output", i, {"channel", "dof", "quantity"})
        ch = _string(ctx, t, "output", i, "channel")
        dof = _string(ctx, t, "output", i, "dof", required=dof_names is not None, default="y")
        if dof_names is not None and dof not in dof_names:
            raise ctx.error(f"unknown DOF {dof!r}; DOFs are {sorted(dof_names)}", "output", i, "dof")
        q = _string(ctx, t, "output", i, "quantity", required=False, default="acceleration")
        if q not in QUANTITIES:
            raise ctx.error(f"quantity={q!r} must be one of {QUANTITIES}", "output", i, "quantity")
        outputs.append(Output(dof, q, ch))
    seen: set[str] = set()
    for table, items in (("input", inputs), ("output", outputs)):
        for i, x in enumerate(items):
            if x.channel in seen:
                raise ctx.error(f"channel {x.channel!r} is used twice", table, i, "channel")
            seen.add(x.channel)
    return inputs, outputs


_CONTROLLER_KEYS = {"name", "law", "gains", "rate_hz", "dof", "drives", "reference", "measures", "velocity_filter",
                    "gain", "saturation", "output_channel", "output_unit", "feedforward"}


def _parse_controllers(ctx, doc, names, inputs):
    out = []
    tbl = "controller"
    for i, t in enumerate(_tables(ctx, doc, tbl)):
        _unknown(ctx, t, tbl, i, _CONTROLLER_KEYS)
        name = _string(ctx, t, tbl, i, "name")
        law = _string(ctx, t, tbl, i, "law")
        if law not in LAWS:
            raise ctx.error(f"law={law!r} must be one of {tuple(LAWS)}", tbl, i, "law")
        if "gains" not in t:
            raise ctx.error("missing required key 'gains'", tbl, i, None, missing="gains")
        gains = t["gains"]
        if not isinstance(gains, dict):
            raise ctx.error(f"gains={_short(gains)} must be a table {{kp = ..., ...}}", tbl, i, "gains")
        for k, v in gains.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ctx.error(f"gain {k}={_short(v)} must be a finite number", tbl, i, "gains")
        rate = _number(ctx, t, tbl, i, "rate_hz", positive=True)
        dof = _string(ctx, t, tbl, i, "dof")
        if dof not in names:
            raise ctx.error(f"unknown DOF {dof!r}; DOFs are {sorted(names)}", tbl, i, "dof")
        drives = t.get("drives", 0)
        if isinstance(drives, bool) or not isinstance(drives, (int, str)):
            raise ctx.error(f"drives={_short(drives)} must be an [[input]] channel or index", tbl, i, "drives")
        if isinstance(drives, int) and not 0 <= drives < len(inputs):
            raise ctx.error(f"drives={drives} must index one of the {len(inputs)} [[input]] tables", tbl, i, "drives")
        if isinstance(drives, str) and drives not in [x.channel for x in inputs]:
            raise ctx.error(f"drives={drives!r} is no [[input]] channel", tbl, i, "drives")
        meas = t.get("measures", ["position"])
        if isinstance(meas, str):
            meas = [meas]
        if not isinstance(meas, list) or not all(m in MEASURES for m in meas):
            raise ctx.error(f"measures={_short(meas)} must be a list of {MEASURES}", tbl, i, "measures")
        taps = None
        if "velocity_filter" in t:
            vf = t["velocity_filter"]
            ok = isinstance(vf, dict) and vf.get("type") == "fir" and set(vf) <= {"type", "taps"}
            ok = ok and isinstance(vf.get("taps"), list) and len(vf["taps"]) > 0
            ok = ok and all(isinstance(h, (int, float)) and not isinstance(h, bool) and math.isfinite(h) for h in vf["taps"])
            if not ok:
                raise ctx.error(f"velocity_filter={_short(vf)} must be {{type = \"fir\", taps = [numbers]}}",
                                tbl, i, "velocity_filter")
            taps = tuple(float(h) for h in vf["taps"])
        gain = _number(ctx, t, tbl, i, "gain", required=False, default=1.0)
        if gain == 0:
            raise ctx.error("gain=0 must be nonzero (N per command unit)", tbl, i, "gain")
        sat = _number(ctx, t, tbl, i, "saturation", positive=True, required=False)
        chans = {k: _string(ctx, t, tbl, i, k, required=False) for k in ("reference", "output_channel", "feedforward")}
        unit = _string(ctx, t, tbl, i, "output_unit", required=False, default="1")
        try:
            out.append(Controller(name=name, law=law, gains=gains, rate_hz=rate, dof=dof, drives=drives,
                                  reference=chans["reference"], measures=tuple(meas), velocity_filter=taps, gain=gain,
                                  saturation=sat,
                                  output_channel=chans["output_channel"], output_unit=unit,
                                  feedforward=chans["feedforward"]))
        except ValueError as exc:
            raise ctx.error(str(exc), tbl, i, "gains") from None
    return out


def _controller_lines(model) -> list[str]:
    out = []
    for c in model.controllers:
        out += ["", "[[controller]]", f"name = {_fmt(c.name)}", f"law = {_fmt(c.law)}",
                "gains = {" + ", ".join(f"{k} = {_fmt(v)}" for k, v in c.gains) + "}",
                f"rate_hz = {_fmt(c.rate_hz)}", f"dof = {_fmt(c.dof)}",
                f"drives = {c.drives if isinstance(c.drives, int) else _fmt(c.drives)}"]  # fmt: skip
        if c.reference is not None:
            out.append(f"reference = {_fmt(c.reference)}")
        if c.measures != ("position",):
            out.append(f"measures = {_fmt(list(c.measures))}")
        if c.velocity_filter is not None:
            out.append(f'velocity_filter = {{type = "fir", taps = {_fmt(list(c.velocity_filter))}}}')
        out.append(f"gain = {_fmt(c.gain)}")
        for key in ("saturation", "output_channel", "feedforward"):
            if getattr(c, key) is not None:
                out.append(f"{key} = {_fmt(getattr(c, key))}")
        if c.output_unit != "1":
            out.append(f"output_unit = {_fmt(c.output_unit)}")
    return out


def _shape_of(v):
    """Shape of a regular nested list (numbers at the leaves), or None if ragged / not numeric."""
    if isinstance(v, list):
        shapes = [_shape_of(x) for x in v]
        if any(s is None for s in shapes) or len(set(shapes)) > 1:
            return None
        return (len(v),) + (shapes[0] if shapes else ())
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return ()
    return None


def _pairs(ctx, tbl, table, i, key, shape):
    """The ``[re, im]`` array `key` of `tbl` as a complex array of `shape` (n_outputs, n_inputs)."""
    v = tbl[key]
    want = shape + (2,)
    got = _shape_of(v)
    if got != want:
        got_txt = "a ragged or non-numeric array" if got is None else ("a number" if got == () else f"shape {got}")
        raise ctx.error(
            f"must be an array of shape (n_outputs={shape[0]}, n_inputs={shape[1]}, 2) "
            f"([re, im] per [[output]] and [[input]] in file order), got {got_txt}",
            table, i, key,
        )
    a = np.array(v, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ctx.error("values must be finite", table, i, key)
    return a[..., 0] + 1j * a[..., 1]


def _parse_modal(ctx, doc) -> PoleResidueModel:
    _unknown(ctx, doc, None, 0, {"kind", "name", "input", "output", "mode", "residual"})
    inputs, outputs = _parse_io(ctx, doc, None)
    if not inputs or not outputs:
        raise ctx.error(
            f"a modal model needs at least one [[input]] and one [[output]], got {len(inputs)} and {len(outputs)}"
        )
    shape = (len(outputs), len(inputs))
    freqs, zetas, residues = [], [], []
    for i, t in enumerate(_tables(ctx, doc, "mode")):
        _unknown(ctx, t, "mode", i, {"frequency_hz", "damping_ratio", "residues"})
        freqs.append(_number(ctx, t, "mode", i, "frequency_hz", positive=True))
        z = _number(ctx, t, "mode", i, "damping_ratio", nonneg=True)
        if z >= 1:
            raise ctx.error(f"damping_ratio={z!r} must be < 1 (an oscillatory mode)", "mode", i, "damping_ratio")
        zetas.append(z)
        if "residues" not in t:
            raise ctx.error("missing required key 'residues'", "mode", i, None, missing="residues")
        residues.append(_pairs(ctx, t, "mode", i, "residues", shape))
    if not freqs:
        raise ctx.error("a modal model needs at least one [[mode]]")
    res = {}
    if "residual" in doc:
        r = doc["residual"]
        if not isinstance(r, dict):
            raise ctx.error("'residual' must be a table [residual]", None, 0, "residual")
        _unknown(ctx, r, "residual", 0, {"lower", "upper"})
        for key in ("lower", "upper"):
            if key in r:
                res[key] = _pairs(ctx, r, "residual", 0, key, shape)
    return PoleResidueModel.from_poles_residues(
        freqs, zetas, np.array(residues), inputs=inputs, outputs=outputs,
        lower=res.get("lower"), upper=res.get("upper"), name=str(doc.get("name", "")),
    )  # fmt: skip


def loads_model(text: str, path: str = "<string>") -> LumpedModel | TransferFunctionModel | PoleResidueModel:
    """Parse a model file's text; see :func:`load_model`.

    Parameters
    ----------
    text : str
        The TOML text of a model file.
    path : str, optional
        Name used in error messages (``path:line``); default ``"<string>"``.

    Returns
    -------
    LumpedModel, TransferFunctionModel or PoleResidueModel
        By the text's ``kind``.

    Raises
    ------
    ModelFileError
        As :func:`load_model`.
    """
    ctx = _Ctx(path, text)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _syntax_error(path, text, exc) from None
    except RecursionError:
        raise ModelFileError(f"{path}: invalid TOML: arrays or tables nested too deeply") from None
    try:
        return _parse_doc(ctx, doc)
    except ModelFileError:
        raise
    except (ValueError, TypeError, ArithmeticError, RecursionError) as exc:  # a fault no check names: still a file error
        raise ModelFileError(f"{path}: invalid model: {type(exc).__name__}: {exc}") from exc


def _syntax_error(path: str, text: str, exc: Exception) -> ModelFileError:
    """``path:N: line N, key 'k': invalid TOML: ...`` from tomllib's message ``(at line N, column C)``."""
    msg = str(exc)
    m = re.search(r"line (\d+)", msg)
    if m:
        line = int(m.group(1))
    else:  # "(at end of document)"
        line = max(1, len(text.rstrip("\n").split("\n")))
        msg += f" (line {line})"
    lines = text.split("\n")
    k = re.match(r"^\s*([A-Za-z0-9_\-.\"' ]+?)\s*=", lines[line - 1]) if 0 < line <= len(lines) else None
    keytxt = f" key {k.group(1).strip()!r}" if k else ""
    return ModelFileError(f"{path}:{line}: line {line}{keytxt}: invalid TOML: {msg}")


def _parse_doc(ctx: _Ctx, doc: dict) -> LumpedModel | TransferFunctionModel | PoleResidueModel:
    kind = doc.get("kind")
    if kind is None:
        raise ctx.error(f"missing required key 'kind' (one of {', '.join(map(repr, KINDS))})", missing="kind")
    if kind == "lumped":
        _unknown(ctx, doc, None, 0, {"kind", "name", "dof", "element", "input", "output", "point", "controller"})
        dofs = []
        for i, t in enumerate(_tables(ctx, doc, "dof")):
            _unknown(ctx, t, "dof", i, {"name", "mass"})
            name = _string(ctx, t, "dof", i, "name")
            if name == GROUND:
                raise ctx.error(f"{GROUND!r} is reserved", "dof", i, "name")
            if name in [d.name for d in dofs]:
                raise ctx.error(f"DOF {name!r} defined twice", "dof", i, "name")
            dofs.append(Dof(name, _number(ctx, t, "dof", i, "mass", positive=True)))
        if not dofs:
            raise ctx.error("a lumped model needs at least one [[dof]]")
        names = {d.name for d in dofs}
        points, shapes = [], []
        for i, t in enumerate(_tables(ctx, doc, "point")):
            _unknown(ctx, t, "point", i, {"name", "shape"})
            pname = _string(ctx, t, "point", i, "name")
            if pname == GROUND or pname in names or pname in points:
                raise ctx.error(f"point {pname!r} is 'ground', a DOF or repeated", "point", i, "name")
            if "shape" not in t:
                raise ctx.error("missing required key 'shape'", "point", i, None, missing="shape")
            sh = t["shape"]
            if _shape_of(sh) is None or len(_shape_of(sh)) != 1 or not 0 < len(sh) <= len(dofs):
                raise ctx.error(f"shape={_short(sh)} must be a list of 1 to {len(dofs)} numbers", "point", i, "shape")
            if (shapes and len(sh) != len(shapes[0])) or not all(math.isfinite(x) for x in sh):
                raise ctx.error("shape must be finite and as long as the other points' shapes", "point", i, "shape")
            points.append(pname)
            shapes.append(tuple(float(x) for x in sh))
        names = names | set(points)
        elements: list[Element] = []
        for i, t in enumerate(_tables(ctx, doc, "element")):
            etype = _string(ctx, t, "element", i, "type")
            if etype not in ELEMENT_TYPES:
                raise ctx.error(f"unknown element type {etype!r}; known: {sorted(ELEMENT_TYPES)}", "element", i, "type")
            _, keys, required = ELEMENT_TYPES[etype]
            _unknown(ctx, t, "element", i, {"type", "between"} | set(keys))
            if "between" not in t:
                raise ctx.error("missing required key 'between'", "element", i, None, missing="between")
            between = t["between"]
            if not (isinstance(between, list) and len(between) == 2 and all(isinstance(b, str) for b in between)):
                raise ctx.error(f"between={between!r} must be two names", "element", i, "between")
            for b in between:
                if b != GROUND and b not in names:
                    raise ctx.error(f"unknown DOF {b!r}; DOFs are {sorted(names)} or {GROUND!r}", "element", i, "between")
            if between[0] == between[1]:
                raise ctx.error(f"between={between!r} joins an end to itself", "element", i, "between")
            params = {}
            for key in keys:
                if key in t or key in required:
                    params[key] = _number(
                        ctx, t, "element", i, key, nonneg=key in _NONNEG and etype not in _SIGNED,
                        positive=key in _POSITIVE
                    )
            try:
                elements.append(make_element(etype, between, **params))
            except ValueError as exc:
                m = re.match(r"^(\w+)=", str(exc))
                key = m.group(1) if m else None
                key = {"force_": "force", "current": "i"}.get(key, key)
                raise ctx.error(str(exc), "element", i, key) from None
        inputs, outputs = _parse_io(ctx, doc, names)
        controllers = _parse_controllers(ctx, doc, names, inputs)
        try:
            if points:
                from vibroscope.models.modal_coordinates import ModalCoordinatesModel

                return ModalCoordinatesModel(dofs=tuple(dofs), elements=tuple(elements), inputs=tuple(inputs),
                                             outputs=tuple(outputs), name=str(doc.get("name", "")),
                                             controllers=tuple(controllers), points=tuple(points),
                                             shapes=tuple(shapes))
            return LumpedModel(dofs=tuple(dofs), elements=tuple(elements), inputs=tuple(inputs),
                               outputs=tuple(outputs), name=str(doc.get("name", "")),
                               controllers=tuple(controllers))
        except ValueError as exc:
            if not controllers:
                raise
            raise ctx.error(str(exc), "controller", 0, None) from None
    if kind == "transfer_function":
        _unknown(ctx, doc, None, 0, {"kind", "name", "num", "den", "input", "output"})
        coeffs = {}
        for key in ("num", "den"):
            v = doc.get(key)
            if v is None:
                raise ctx.error(f"missing required key {key!r}", missing=key)
            if not (isinstance(v, list) and v and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in v)):
                raise ctx.error(f"{key}={_short(v)} must be a list of numbers", None, 0, key)
            coeffs[key] = v
        inputs, outputs = _parse_io(ctx, doc, None)
        if len(inputs) != 1 or len(outputs) != 1:
            raise ctx.error(f"a transfer function needs one [[input]] and one [[output]], got {len(inputs)} and {len(outputs)}")
        try:
            return TransferFunctionModel(tuple(coeffs["num"]), tuple(coeffs["den"]), inputs[0], outputs[0], str(doc.get("name", "")))
        except ValueError as exc:
            raise ctx.error(str(exc), None, 0, "den") from None
    if kind == "modal":
        return _parse_modal(ctx, doc)
    raise ctx.error(f"kind={_short(kind)} must be one of {', '.join(map(repr, KINDS))}", None, 0, "kind")


def load_model(path) -> LumpedModel | TransferFunctionModel | PoleResidueModel:
    """Load a model from a TOML model file.

    Parameters
    ----------
    path : str or path-like
        The ``.toml`` file (schema in the module docstring).

    Returns
    -------
    LumpedModel, TransferFunctionModel or PoleResidueModel
        By the file's ``kind``: ``"lumped"``, ``"transfer_function"`` or ``"modal"``.

    Raises
    ------
    ModelFileError
        For invalid TOML, unknown keys, missing keys or DOFs, and non-physical values
        (negative mass or stiffness, frequency <= 0, damping ratio outside [0, 1), residue
        arrays whose shape is not (n_outputs, n_inputs, 2), ...); the message names
        ``file:line`` and the key.

    See Also
    --------
    loads_model : The same from the text of a model file.
    dumps_model : A model as the text of a model file.
    vibroscope.simulate : The loaded model's response to an input.

    Examples
    --------
    One DOF of 2 kg on a 5e4 N/m spring: its natural frequency is ``sqrt(k/m) / (2 pi)`` =
    25.16 Hz.

    >>> import math, tempfile
    >>> from pathlib import Path
    >>> text = '''
    ... kind = "lumped"
    ... [[dof]]
    ... name = "m1"
    ... mass = 2.0
    ... [[element]]
    ... type = "spring"
    ... between = ["m1", "ground"]
    ... k = 5.0e4
    ... '''
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = Path(tmp) / "sdof.toml"
    ...     _ = path.write_text(text)
    ...     model = load_model(path)
    >>> model.dof_names
    ('m1',)
    >>> f_n = float(model.modes().natural_frequencies[0])
    >>> round(f_n, 2)
    25.16
    >>> math.isclose(f_n, math.sqrt(5.0e4 / 2.0) / (2 * math.pi), rel_tol=1e-9)
    True
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ModelFileError(f"{path}: cannot read model file: {exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ModelFileError(
            f"{path}:{line}: line {line}: not a text (UTF-8) model file: byte {exc.start} is {data[exc.start]:#04x}"
        ) from None
    return loads_model(text, str(path))


def _fmt(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return repr(float(v))


def _io_lines(inputs, outputs, with_dof=True) -> list[str]:
    """``[[input]]``/``[[output]]`` tables; ``with_dof="label"`` writes a ``dof`` only where it
    is not the label's default (``"u"``, ``"y"``)."""
    out = []
    for i in inputs:
        out += ["", "[[input]]", f"channel = {_fmt(i.channel or '/input.x')}"]
        if with_dof is True or (with_dof == "label" and i.dof != "u"):
            out.append(f"dof = {_fmt(i.dof)}")
        out.append(f"quantity = {_fmt(i.quantity)}")
        if i.saturation is not None:
            out.append(f"saturation = {_fmt(i.saturation)}")
            if i.saturation_law != "clip":
                out.append(f"saturation_law = {_fmt(i.saturation_law)}")
        if i.delay:
            out.append(f"delay = {_fmt(i.delay)}")
        if i.offset:
            out.append(f"offset = {_fmt(i.offset)}")
    for o in outputs:
        out += ["", "[[output]]", f"channel = {_fmt(o.channel or '/output.x')}"]
        if with_dof is True or (with_dof == "label" and o.dof != "y"):
            out.append(f"dof = {_fmt(o.dof)}")
        out.append(f"quantity = {_fmt(o.quantity)}")
    return out


def _pairs_fmt(a) -> str:
    """A complex array (n_outputs, n_inputs) as nested ``[re, im]`` pairs."""
    a = np.asarray(a, dtype=complex)
    return _fmt([[[z.real, z.imag] for z in row] for row in a])


def dumps_model(model: LumpedModel | TransferFunctionModel | PoleResidueModel) -> str:
    """The TOML text of `model` (inverse of :func:`loads_model`; floats written by ``repr``,
    so a round trip is exact).

    Parameters
    ----------
    model : LumpedModel, TransferFunctionModel or PoleResidueModel
        The model to write.

    Returns
    -------
    str
        The model file's text, ending in a newline.
    """
    if isinstance(model, PoleResidueModel):
        lines = ['kind = "modal"']
        if model.name:
            lines.append(f"name = {_fmt(model.name)}")
        lines += _io_lines(model.inputs, model.outputs, with_dof="label")
        for f, z, R in zip(model.natural_frequencies, model.damping_ratios, model.residues):
            lines += ["", "[[mode]]", f"frequency_hz = {_fmt(f)}", f"damping_ratio = {_fmt(z)}",
                      f"residues = {_pairs_fmt(R)}"]  # fmt: skip
        if np.any(model.lower_residual != 0) or np.any(model.upper_residual != 0):
            lines += ["", "[residual]"]
            if np.any(model.lower_residual != 0):
                lines.append(f"lower = {_pairs_fmt(model.lower_residual)}")
            if np.any(model.upper_residual != 0):
                lines.append(f"upper = {_pairs_fmt(model.upper_residual)}")
        return "\n".join(lines) + "\n"
    if isinstance(model, TransferFunctionModel):
        lines = ['kind = "transfer_function"']
        if model.name:
            lines.append(f"name = {_fmt(model.name)}")
        lines += [f"num = {_fmt(model.num)}", f"den = {_fmt(model.den)}"]
        lines += _io_lines(model.inputs, model.outputs, with_dof=False)
        return "\n".join(lines) + "\n"
    lines = ['kind = "lumped"']
    if model.name:
        lines.append(f"name = {_fmt(model.name)}")
    for d in model.dofs:
        lines += ["", "[[dof]]", f"name = {_fmt(d.name)}", f"mass = {_fmt(d.mass)}  # kg"]
    for pname, shape in zip(model.point_names(), getattr(model, "shapes", ())):
        lines += ["", "[[point]]", f"name = {_fmt(pname)}", f"shape = {_fmt(shape)}"]
    for e in model.elements:
        _, keys, _ = ELEMENT_TYPES[e.type]
        lines += ["", "[[element]]", f"type = {_fmt(e.type)}", f"between = {_fmt(list(e.between))}"]
        seen = set()
        for fkey, attr in keys.items():
            if attr in seen:
                continue
            seen.add(attr)
            value = getattr(e, attr)
            if value is not None:  # an optional parameter left unset (friction force_neg)
                lines.append(f"{fkey} = {_fmt(value)}")
    lines += _io_lines(model.inputs, model.outputs)
    lines += _controller_lines(model)
    return "\n".join(lines) + "\n"


def dump_model(model: LumpedModel | TransferFunctionModel | PoleResidueModel, path) -> None:
    """Write `model` as a TOML model file that :func:`load_model` reads back equal.

    Parameters
    ----------
    model : LumpedModel, TransferFunctionModel or PoleResidueModel
        The model to write (text as :func:`dumps_model`).
    path : str or path-like
        The file to write (UTF-8), replaced if it exists: written under a temporary name in
        the same directory and renamed when complete, so a failed write leaves the old file.
    """
    from vibroscope._checks import atomic_file

    text = dumps_model(model)
    with atomic_file(path) as tmp, open(tmp, "x", encoding="utf-8") as fh:
        fh.write(text)
