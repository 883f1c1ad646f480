"""Comparative sweeps: the founding paper's "input data from file where one parameter changes".

A :class:`SweepModel` builds a SISO system from named parameters (SI); :func:`sweep` runs
it over cases (one dict of parameters each), on common time and frequency grids, and
returns the step (indicial) responses, Bode data and the dynamic criteria of every case
with the paper's influence coefficients (eq. 2-3) from the first case to each later one.

Built-in models (:func:`builtin_sweep_model`): ``pneumatic`` (velocity per air flow of
the pneumatic motor), ``hydraulic`` (P position loop of the valve-controlled cylinder,
parameters of ``HYDRAULIC_NOMINAL`` plus ``k_p``), ``block-schema`` (closed loop y/r of the
PI + PT1 correction schema with a PT2 plant, parameters ``K``, ``omega_n``, ``zeta``).
:func:`model_file_sweep_model` reads a TOML model file whose sweep columns are dotted keys
into the file (``dof.m1.mass``, ``element.0.k``, ``den.2``).

References
----------
.. [1] A. Olaru and S. Olaru, "Assisted dynamic behavior optimization with LabVIEW
   instrumentation", Proc. CSIT vol. 1, 2011, eq. (2)-(3).
"""

from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import control
import numpy as np

from vibroscope.errors import VibroscopeError
from vibroscope.instruments.block_schema import paper_block_schema
from vibroscope.instruments.hydraulic import HYDRAULIC_NOMINAL, hydraulic_closed_loop, hydraulic_comparison
from vibroscope.instruments.influence import (critical_frequency, differentiate, paper_coefficient, peak_acceleration,
                                              resonance_frequency, time_grid)
from vibroscope.instruments.lti import BodeResult, StepResult, bode, clean_tf, step_response
from vibroscope.instruments.pneumatic import PNEUMATIC_NOMINAL, pneumatic_motor
from vibroscope.models.modelfile import load_model, loads_model

__all__ = [
    "BUILTIN_SWEEP_MODELS",
    "CRITERIA",
    "SweepModel",
    "SweepResult",
    "builtin_sweep_model",
    "model_file_sweep_model",
    "sweep",
    "set_dotted",
    "dumps_toml",
]

#: names of the built-in models of :func:`builtin_sweep_model`
BUILTIN_SWEEP_MODELS = ("pneumatic", "hydraulic", "block-schema")
#: the dynamic criteria of each case: 10-90 % rise time, peak acceleration of the step,
#: resonance frequency, -3 dB critical frequency
CRITERIA = ("t_r", "a_max", "nu_r", "nu_c")


@dataclass(frozen=True, kw_only=True)
class SweepModel:
    """A system built from named parameters, for :func:`sweep`.

    Attributes
    ----------
    name : str
        Model name (a built-in name or the model file's stem).
    factory : callable
        ``factory(**params) -> control.TransferFunction`` (SISO).
    nominal : dict
        Nominal parameters (SI); a case overrides some of them.  Empty: any parameter the
        factory accepts.
    order : int
        Number of time derivatives from the system's output to an acceleration (1 for a
        velocity output, 2 for a position).
    quantity : str
        What the output is (``"velocity per flow"``).
    unit : str
        Its unit (``"m/s per m³/s"``), empty when dimensionless or unknown.
    a_max_unit : str
        Unit of the peak-acceleration criterion.
    """

    name: str
    factory: Callable[..., control.TransferFunction]
    nominal: dict
    order: int
    quantity: str
    unit: str
    a_max_unit: str = "1/s² per unit step"


def builtin_sweep_model(name: str) -> SweepModel:
    """One of :data:`BUILTIN_SWEEP_MODELS` (see the module notes).

    Parameters
    ----------
    name : {"pneumatic", "hydraulic", "block-schema"}
        The model.

    Returns
    -------
    SweepModel
        The named model.
    """
    if name == "pneumatic":
        return SweepModel(name=name, factory=lambda **p: pneumatic_motor(**p, output="velocity"),
                          nominal=dict(PNEUMATIC_NOMINAL), order=1, quantity="velocity per flow",
                          unit="m/s per m³/s", a_max_unit="m/s² per m³/s")
    if name == "hydraulic":
        nominal = dict(HYDRAULIC_NOMINAL, k_p=hydraulic_comparison().gains_p["k_p"])

        def hyd(k_p, **p):
            return hydraulic_closed_loop(k_p, **p)

        return SweepModel(name=name, factory=hyd, nominal=nominal, order=2, quantity="position x/r", unit="-")
    if name == "block-schema":
        def bs(K, omega_n, zeta):
            plant = control.tf([K], [1.0 / omega_n**2, 2.0 * zeta / omega_n, 1.0])
            return paper_block_schema(plant=plant).transfer("y")

        return SweepModel(name=name, factory=bs, nominal={"K": 1.0, "omega_n": 5.0, "zeta": 0.7}, order=2,
                          quantity="plant output y/r", unit="-")
    raise ValueError(f"{name=} is not a built-in model; known: {', '.join(BUILTIN_SWEEP_MODELS)}")


# --------------------------------------------------------------------------- model files


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps_toml(doc: Mapping) -> str:
    """TOML text of a parsed model file, readable back by :mod:`tomllib`.

    Parameters
    ----------
    doc : mapping
        As :func:`tomllib.loads` returns it for a model file: scalars and lists at the top,
        tables, and arrays of tables, one level deep.

    Returns
    -------
    str
        ``tomllib.loads(dumps_toml(doc)) == doc``.
    """
    def is_tables(v):
        return isinstance(v, list) and bool(v) and isinstance(v[0], dict)

    lines = [f"{k} = {_toml_value(v)}" for k, v in doc.items() if not isinstance(v, dict) and not is_tables(v)]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += ["", f"[{k}]"] + [f"{kk} = {_toml_value(vv)}" for kk, vv in v.items()]
        elif is_tables(v):
            for item in v:
                lines += ["", f"[[{k}]]"] + [f"{kk} = {_toml_value(vv)}" for kk, vv in item.items()]
    return "\n".join(lines) + "\n"


def _index(cur: list, part: str, key: str, path) -> int:
    """Index into a list: a number, or the ``name`` of an entry of an array of tables."""
    if part.lstrip("-").isdigit():
        idx = int(part)
    else:
        names = [t.get("name") if isinstance(t, dict) else None for t in cur]
        if part not in names:
            raise VibroscopeError(f"{path}: sweep column {key!r}: no entry named {part!r}")
        idx = names.index(part)
    if not -len(cur) <= idx < len(cur):
        raise VibroscopeError(f"{path}: sweep column {key!r}: index {idx} out of range")
    return idx


def set_dotted(doc: dict, key: str, value: float, path) -> None:
    """Set ``key`` (``mass`` / ``dof.m1.mass`` / ``element.0.k`` / ``num.1``) in a parsed TOML document.

    Parameters
    ----------
    doc : dict
        The document, changed in place.
    key : str
        Dotted key: table keys, list indices, or the ``name`` of an entry of an array of tables.
    value : float
        New value.
    path : str or path-like
        The model file, for error messages.

    Raises
    ------
    VibroscopeError
        If the key does not address an existing value.
    """
    parts = key.split(".")
    cur = doc
    for i, part in enumerate(parts):
        if isinstance(cur, list):
            part = _index(cur, part, key, path)
        elif isinstance(cur, dict):
            if part not in cur:
                raise VibroscopeError(f"{path}: sweep column {key!r}: no key {part!r} in the model file")
        else:
            raise VibroscopeError(f"{path}: sweep column {key!r}: {part!r} is below a value")
        if i == len(parts) - 1:
            cur[part] = value
        else:
            cur = cur[part]


def model_file_sweep_model(path) -> SweepModel:
    """A model file as a sweep model: sweep columns are dotted TOML keys overriding the file's values.

    Examples of columns: ``dof.m1.mass`` (array of tables addressed by ``name``),
    ``element.0.k`` (by index), ``den.2`` (a list entry).  The system compared is the
    first-input / first-output transfer function (the linear part of a lumped model).

    Parameters
    ----------
    path : str or path-like
        The ``.toml`` model file (:func:`vibroscope.models.modelfile.load_model`).

    Returns
    -------
    SweepModel
        The model of the file, its columns the dotted keys.
    """
    path = Path(path)
    load_model(path)  # validate once, with the file's own error messages
    doc = tomllib.loads(path.read_text())

    def factory(**overrides):
        d = copy.deepcopy(doc)
        for k, v in overrides.items():
            set_dotted(d, k, v, path)
        m = loads_model(dumps_toml(d), path=str(path))
        if hasattr(m, "state_space"):
            return clean_tf(m.state_space()[0, 0])
        return control.tf(m.tf())

    return SweepModel(name=path.stem, factory=factory, nominal={}, order=2, quantity="output per input", unit="")


# --------------------------------------------------------------------------- the sweep


@dataclass(frozen=True, eq=False, kw_only=True)
class SweepResult:
    """Responses and criteria of every case of a sweep.

    Attributes
    ----------
    model : SweepModel
        The model swept.
    header : tuple of str
        Parameter names of the cases.
    cases : tuple of dict
        Parameters of each case (SI).
    labels : tuple of str
        ``"A=0.006, V=0.00075"`` per case.
    systems : tuple of control.TransferFunction
        The system of each case.
    steps : tuple of StepResult
        Unit step responses on a common time grid.
    bodes : tuple of BodeResult
        Bode data on a common frequency grid.
    criteria : tuple of dict
        :data:`CRITERIA` of each case: ``t_r`` (s), ``a_max``, ``nu_r`` (Hz), ``nu_c`` (Hz).
    """

    model: SweepModel
    header: tuple[str, ...]
    cases: tuple[dict, ...]
    labels: tuple[str, ...]
    systems: tuple
    steps: tuple[StepResult, ...]
    bodes: tuple[BodeResult, ...]
    criteria: tuple[dict, ...]

    def influence_rows(self) -> list[tuple[str, list[str], list[float] | None]]:
        """Influence coefficients from the first case to each later one (paper eq. 2-3).

        Returns
        -------
        list of (parameter, changed, coefficients)
            Per later case: the one changed parameter (empty when not exactly one changed),
            the names of the changed parameters, and the coefficient of each of
            :data:`CRITERIA` (nan where a criterion is non-finite or zero at the first
            case), or None when not exactly one parameter changed.
        """
        first = self.cases[0]
        varied = [h for h in self.header if len({c[h] for c in self.cases}) > 1]
        rows = []
        for k in range(1, len(self.cases)):
            changed = [h for h in varied if self.cases[k][h] != first[h]]
            if len(changed) != 1:
                rows.append(("", changed, None))
                continue
            h = changed[0]
            values = [_coefficient(self.criteria[0][n], self.criteria[k][n], first[h], self.cases[k][h]) for n in CRITERIA]
            rows.append((h, changed, values))
        return rows


def _coefficient(pcd_initial: float, pcd_final: float, pcf_initial: float, pcf_final: float) -> float:
    if math.isfinite(pcd_initial) and math.isfinite(pcd_final) and pcd_initial != 0:
        return paper_coefficient(pcd_initial, pcd_final, pcf_initial, pcf_final)
    return float("nan")


def _frequency_grid(systems) -> np.ndarray:
    """From a decade and a half below the slowest pole to a decade above the fastest, Hz."""
    poles = np.concatenate([control.poles(g) for g in systems])
    poles = poles[np.abs(poles) > 1e-9]
    fast = np.max(np.abs(poles)) if poles.size else 10.0
    return np.logspace(np.log10(np.min(np.abs(poles)) / 2 / np.pi) - 1.5, np.log10(fast / 2 / np.pi) + 1, 600)


def _criteria(g, step: StepResult, t: np.ndarray, order: int) -> dict[str, float]:
    return {
        "t_r": step.rise_time_s,
        "a_max": peak_acceleration(differentiate(g, order - 1), t),
        "nu_r": resonance_frequency(g),
        "nu_c": critical_frequency(g),
    }


def _systems(model: SweepModel, header: Sequence[str], cases: Sequence[Mapping[str, float]]) -> list:
    unknown = [h for h in header if model.nominal and h not in model.nominal]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown} for model {model.name!r}; known: {sorted(model.nominal)}")
    systems = []
    for k, c in enumerate(cases):
        try:
            systems.append(model.factory(**{**model.nominal, **c}))
        except (ValueError, TypeError) as exc:
            raise ValueError(f"row {k + 1}: {exc}") from None
    return systems


def sweep(model: SweepModel, header: Sequence[str], cases: Sequence[Mapping[str, float]]) -> SweepResult:
    """Step responses, Bode data and criteria of `model` for every case.

    Parameters
    ----------
    model : SweepModel
        The system's factory and nominal parameters.
    header : sequence of str
        Parameter names, in the order of the labels.
    cases : sequence of mapping
        Parameters of each case (SI), overriding ``model.nominal``.

    Returns
    -------
    SweepResult
        On a common time grid (6 slowest decay times, 4001 samples) and frequency grid
        (600 log-spaced points around the poles of all cases).

    Raises
    ------
    ValueError
        For a parameter the model does not know, or a case the factory rejects (the
        message names the row, 1 for the first case).
    """
    header = tuple(header)
    cases = tuple(dict(c) for c in cases)
    systems = _systems(model, header, cases)
    t = time_grid(*systems, n=4001, horizon=6.0, zero_tol=1e-9)
    f = _frequency_grid(systems)
    steps = tuple(step_response(g, t) for g in systems)
    return SweepResult(
        model=model,
        header=header,
        cases=cases,
        labels=tuple(", ".join(f"{h}={c[h]:g}" for h in header) for c in cases),
        systems=tuple(systems),
        steps=steps,
        bodes=tuple(bode(g, f) for g in systems),
        criteria=tuple(_criteria(g, s, t, model.order) for g, s in zip(systems, steps)),
    )
