"""Every public function and class of vibroscope documents each of its parameters (numpydoc).

In the spirit of python-control's ``control/tests/docstrings_test.py``: the test walks every
module of the package (:func:`pkgutil.walk_packages`), takes the names of its ``__all__`` that
are functions or classes defined in vibroscope, and checks

- that each has a docstring, with a ``Parameters`` section when it takes parameters;
- that each parameter is listed in a numpydoc section (``Parameters``, ``Other Parameters``, or,
  for a class, ``Attributes``, or the ``__init__`` docstring): a line ``name : type`` (or
  ``name1, name2 : type``, or ``name`` alone) at the left margin of the section.

Classes are checked for their constructor's parameters and for those of each public method
(and class/static method) defined in the class body. ``*args``, ``**kwargs`` and parameters
whose name starts with ``_`` are not required; nor are the constructor parameters of exceptions
and enums. An object re-exported by a package is checked once, under its shortest public name
(``vibroscope.spectral.welch``, not ``vibroscope.spectral.estimators.welch``; the curated
top-level names of :mod:`vibroscope` come last, so not ``vibroscope.welch`` either). The CLI's
``vibroscope.commands`` modules are included: their ``__all__`` is public too.

Known gaps are listed in :data:`UNDOCUMENTED` and marked ``xfail(strict=True)``: documenting one
makes its test pass and fail the run until the entry is removed, so the list stays exact.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
from collections.abc import Iterator

import pytest

import vibroscope

# Modules that need an optional dependency may be skipped when it is missing (the [rerun] and
# [dask] extras); any other import error fails test_every_module_imports.
OPTIONAL = ("rerun", "dask")

# Known gaps, public name -> parameters not (yet) documented; ``None``: the object has no
# docstring, or none with a Parameters section. Each entry is an xfail(strict=True) test.
# Regenerate with ``python tests/test_docstrings.py`` (prints this dict for the current tree).
# BEGIN UNDOCUMENTED
UNDOCUMENTED_BY_OBJECT: dict[str, tuple[str | None, ...]] = {
    # vibroscope.commands
    "vibroscope.commands.analyse.add_parser": (None, "sub"),
    "vibroscope.commands.analyse.analyse_log": (None, "log", "input", "outputs", "fs", "progress"),
    "vibroscope.commands.analyse.run": (None, "args"),
    "vibroscope.commands.demo.add_parser": (None, "sub"),
    "vibroscope.commands.demo.make_demo_log": (None, "path", "fs", "duration", "seed", "noise"),
    "vibroscope.commands.demo.run": (None, "args"),
    "vibroscope.commands.gap.add_parser": (None, "sub"),
    "vibroscope.commands.gap.run": (None, "args"),
    "vibroscope.commands.modal.add_parser": (None, "sub"),
    "vibroscope.commands.modal.run": (None, "args"),
    "vibroscope.commands.simulate.add_parser": (None, "sub"),
    "vibroscope.commands.simulate.run": (None, "args"),
    "vibroscope.commands.simulate.simulate_to_signals": (None, "model", "excitation", "input_log", "fs",
        "duration", "noise", "seed", "t0"),
    # vibroscope.gap
    "vibroscope.gap.GapReport.plot": (None, "out_dir"),
    "vibroscope.gap.diagnosis.as_lumped": (None, "model"),
    "vibroscope.gap.effects.EffectSpec": ("meta",),
    "vibroscope.gap.effects.EffectSpec.apply": (None, "model", "p"),
    "vibroscope.gap.effects.LinearParams": (None, "model", "which"),
    "vibroscope.gap.effects.LinearParams.apply": (None, "model", "theta"),
    "vibroscope.gap.effects.LinearParams.changed": (None, "theta", "tol"),
    "vibroscope.gap.effects.LinearParams.values": (None, "model"),
    "vibroscope.gap.effects.connections": (None, "model"),
    "vibroscope.gap.fit.LogSimulator.run": (None, "model", "n", "fast"),
    "vibroscope.gap.fit.fit_linear_frf": ("p_starts",),
    "vibroscope.gap.fit.fit_time_domain": ("fast", "max_nfev", "diff_step"),
    "vibroscope.gap.fit.frf_residual": (None, "model", "f", "H", "w"),
    "vibroscope.gap.measure.NoiseFloor": (None, "nrmse", "method", "psd_level", "excited_band"),
    "vibroscope.gap.measure.input_levels": (None, "u", "fs", "window_s", "max_levels"),
    "vibroscope.gap.measure.locate_bands": ("energy", "min_share", "max_bands"),
    "vibroscope.gap.measure.make_split": ("validation_fraction", "screen_s"),
    "vibroscope.gap.measure.noise_floor": (None, "ys", "us", "masks", "fs", "nperseg"),
    "vibroscope.gap.measure.regime_gaps": (None, "y", "yhat", "mask", "states", "u", "level_labels"),
    "vibroscope.gap.report.Band.to_dict": (None,),
    "vibroscope.gap.report.Candidate.to_dict": (None,),
    "vibroscope.gap.report.ChannelGap": (None, "channel", "gap", "gap_after", "rms_error",
        "rms_error_after", "unit"),
    "vibroscope.gap.report.ChannelGap.to_dict": (None,),
    "vibroscope.gap.report.RegimeGap.to_dict": (None,),
    "vibroscope.gap.report.SignatureTest.to_dict": (None,),
    # vibroscope.instruments
    "vibroscope.instruments.block_schema.BlockSchema.block_bode": (None, "frequencies_hz"),
    "vibroscope.instruments.block_schema.BlockSchema.feedback": (None, "forward", "back", "sign", "name"),
    "vibroscope.instruments.block_schema.BlockSchema.parallel": (None, "names", "name"),
    "vibroscope.instruments.block_schema.BlockSchema.series": (None, "names", "name"),
    "vibroscope.instruments.block_schema.BlockSchema.transfers": (None, "from_"),
    "vibroscope.instruments.hydraulic.HydraulicComparison.plot": (None, "axes"),
    "vibroscope.instruments.hydraulic.step_velocity": (None, "r"),
    "vibroscope.instruments.influence.InfluenceTable.to_markdown": (None, "digits"),
    "vibroscope.instruments.influence.check_paper_claims": (None, "table"),
    "vibroscope.instruments.influence.critical_frequency": (None, "sys", "level_db"),
    "vibroscope.instruments.influence.peak_acceleration": (None, "sys", "t", "amplitude"),
    "vibroscope.instruments.influence.relative_change": (None, "initial", "final"),
    "vibroscope.instruments.influence.resonance_frequency": (None, "sys"),
    "vibroscope.instruments.influence.response_time": (None, "sys", "t"),
    "vibroscope.instruments.lti.BodeResult.plot": (None, "axes", "label"),
    "vibroscope.instruments.lti.NyquistResult.plot": (None, "ax", "label", "mirror"),
    "vibroscope.instruments.lti.StepResult.plot": (None, "ax", "label"),
    "vibroscope.instruments.mr_damper.MRDamperParams.at_current": (None, "i"),
    "vibroscope.instruments.mr_damper.MRDamperResult.dissipated_energy": (None, "t_start", "t_stop"),
    "vibroscope.instruments.mr_damper.MRDamperResult.loop_energy": (None, "period_s"),
    "vibroscope.instruments.mr_damper.MRDamperResult.plot": (None, "axes", "label", "last_s"),
    "vibroscope.instruments.mr_damper.mr_damper_force": (None, "x", "xdot", "y", "z", "coeffs"),
    "vibroscope.instruments.pneumatic.pneumatic_natural_frequency_rad_s": (None, "A", "V", "m", "a_m",
        "b_m", "chi", "dp"),
    # vibroscope.io
    "vibroscope.io.LogInfo": (None, "path", "profile", "library", "message_count", "start_ns", "end_ns",
        "topics", "skipped", "warnings"),
    "vibroscope.io.LogInfo.topic": (None, "name"),
    "vibroscope.io.select.is_bookkeeping": (None, "path"),
    # vibroscope.modal
    "vibroscope.modal._peaks.band_indices": (None, "frequencies", "fmin", "fmax"),
    "vibroscope.modal._peaks.parabolic_vertex": (None, "y", "k"),
    "vibroscope.modal.automatic.ssi_lags": (None, "fs", "f_low", "n_samples", "periods"),
    # vibroscope.models
    "vibroscope.models.Backlash": (None, "between", "k", "gap"),
    "vibroscope.models.Backlash.force": (None, "d", "v", "state"),
    "vibroscope.models.BoucWen": (None, "between", "alpha", "beta", "gamma", "delta", "nu"),
    "vibroscope.models.BoucWen.force": (None, "d", "v", "state"),
    "vibroscope.models.BoucWen.state_derivative": (None, "d", "v", "state"),
    "vibroscope.models.CubicSpring": (None, "between", "k3", "k"),
    "vibroscope.models.CubicSpring.force": (None, "d", "v", "state"),
    "vibroscope.models.Damper": (None, "between", "c"),
    "vibroscope.models.Damper.force": (None, "d", "v", "state"),
    "vibroscope.models.Dof": (None, "name", "mass"),
    "vibroscope.models.Element": (None, "between"),
    "vibroscope.models.Element.force": (None, "d", "v", "state"),
    "vibroscope.models.Element.state_derivative": (None, "d", "v", "state"),
    "vibroscope.models.Friction": (None, "between", "force_", "v_eps"),
    "vibroscope.models.Friction.force": (None, "d", "v", "state"),
    "vibroscope.models.LumpedModel.chain": (None, "masses", "springs", "dampers", "input_dof",
        "input_channel", "output_quantity", "nonlinear", "name"),
    "vibroscope.models.LumpedModel.dof_index": (None, "name"),
    "vibroscope.models.LumpedModel.element_vector": (None, "element"),
    "vibroscope.models.MRDamper": (None, "between", "current", "alpha_a", "alpha_b", "c0_a", "c0_b", "c1_a",
        "c1_b", "k0", "k1", "gamma", "beta", "A", "n"),
    "vibroscope.models.MRDamper.force": (None, "d", "v", "state"),
    "vibroscope.models.MRDamper.from_coefficients": (None, "between", "coeffs"),
    "vibroscope.models.MRDamper.state_derivative": (None, "d", "v", "state"),
    "vibroscope.models.Output": (None, "dof", "quantity", "channel"),
    "vibroscope.models.Spring": (None, "between", "k"),
    "vibroscope.models.Spring.force": (None, "d", "v", "state"),
    "vibroscope.models.boucwen_benchmark.simulate_boucwen_benchmark": (None, "u", "fs", "periodic",
        "n_periods", "oversample"),
    "vibroscope.models.excitation.Excitation": (None, "kind", "params"),
    "vibroscope.models.excitation.Excitation.generate": (None, "fs", "n", "seed"),
    "vibroscope.models.excitation.band_limited_random": (None, "fs", "n", "duration", "f_lo", "f_hi", "rms",
        "seed"),
    "vibroscope.models.excitation.impact": (None, "fs", "n", "duration", "peak", "pulse", "t_start",
        "seed"),
    "vibroscope.models.excitation.multisine": ("fs", "n", "duration", "f_lo", "f_hi", "rms", "seed"),
    "vibroscope.models.excitation.parse_excitation": (None, "spec"),
    "vibroscope.models.excitation.sine_sweep": (None, "fs", "n", "duration", "f0", "f1", "amplitude",
        "kind", "seed"),
    "vibroscope.models.excitation.step": (None, "fs", "n", "duration", "amplitude", "t_start", "seed"),
    "vibroscope.models.make_element": (None, "type", "between"),
    "vibroscope.models.modelfile.TransferFunctionModel.frf": (None, "frequencies_hz"),
    "vibroscope.models.modelfile.TransferFunctionModel.input_channels": (None,),
    "vibroscope.models.modelfile.TransferFunctionModel.output_channels": (None,),
    "vibroscope.models.modelfile.dump_model": (None, "model", "path"),
    "vibroscope.models.modelfile.dumps_model": (None, "model"),
    "vibroscope.models.modelfile.loads_model": (None, "text", "path"),
    # vibroscope.pipeline
    "vibroscope.pipeline.IdentifySettings": (None, "input", "outputs", "nperseg", "window", "fmin", "fmax",
        "n_modes", "estimator", "prominence", "method", "f_low", "band", "select", "period"),
    "vibroscope.pipeline.decimate": (None, "signals", "fmax"),
    "vibroscope.pipeline.default_nperseg": (None, "n", "fs", "fmin", "averages"),
    "vibroscope.pipeline.summary_dict": (None, "analysis", "source", "true_modes"),
    # vibroscope.signals
    "vibroscope.signals.Signals.index": (None, "channel"),
    "vibroscope.signals.Signals.select": (None, "channels"),
    "vibroscope.signals.Signals.stack": (None, "parts"),
    # vibroscope.spectral
    "vibroscope.spectral.CrossSpectralAccumulator.merge": (None, "other"),
    "vibroscope.spectral.CrossSpectralAccumulator.result": (None, "scaling"),
    "vibroscope.spectral.CrossSpectralAccumulator.update": (None, "x"),
    "vibroscope.spectral.CrossSpectralMatrix.band": (None, "fmin", "fmax"),
    "vibroscope.spectral.CrossSpectralMatrix.index": (None, "channel"),
    "vibroscope.spectral.CrossSpectralMatrix.select": (None, "channels"),
    "vibroscope.spectral.FRF.plot": (None, "output", "input", "fig"),
    "vibroscope.spectral.FRF.to": (None, "kind"),
    "vibroscope.spectral.OperatingShape.plot": (None, "coords"),
    "vibroscope.spectral.Spectrum.plot": (None, "ax", "db", "channels"),
    "vibroscope.spectral.frf_kind": (None, "input_units", "output_units"),
    # vibroscope.viewers
    "vibroscope.viewers._common.match_modes": (None, "f_est", "f_true"),
    "vibroscope.viewers._common.mode_label": (None, "f", "zeta"),
    "vibroscope.viewers.gap_figures.candidate_label": (None, "candidate"),
    "vibroscope.viewers.gap_figures.held_out_spans": (None, "validation"),
    "vibroscope.viewers.gap_figures.verdict_index": (None, "report"),
    "vibroscope.viewers.gap_figures.where_label": (None, "where"),
    "vibroscope.viewers.gap_figures.zoom_window": (None, "traces", "width_s"),
    "vibroscope.viewers.instruments.plot_bode": (None, "result", "axes", "label"),
    "vibroscope.viewers.instruments.plot_hydraulic_comparison": (None, "comparison", "axes"),
    "vibroscope.viewers.instruments.plot_mr_loops": (None, "result", "axes", "label", "last_s"),
    "vibroscope.viewers.instruments.plot_nyquist": (None, "result", "ax", "label", "mirror"),
    "vibroscope.viewers.instruments.plot_step": (None, "result", "ax", "label"),
    "vibroscope.viewers.rerun_view.mode_entity": (None, "r", "f"),
}
# END UNDOCUMENTED
UNDOCUMENTED = {(q, p) for q, ps in UNDOCUMENTED_BY_OBJECT.items() for p in ps}

SECTIONS = ("Parameters", "Other Parameters", "Attributes")


def _walk() -> tuple[dict[str, object], dict[str, str]]:
    modules, failed = {"vibroscope": vibroscope}, {}
    for info in pkgutil.walk_packages(vibroscope.__path__, "vibroscope."):
        try:
            modules[info.name] = importlib.import_module(info.name)
        except ImportError as exc:
            failed[info.name] = f"{type(exc).__name__}: {exc}"
    return modules, failed


MODULES, IMPORT_FAILURES = _walk()


def _public_objects() -> dict[str, object]:
    """Shortest public name -> function or class, over every module's ``__all__``."""
    found: dict[int, tuple[str, object]] = {}
    # the room's name first (vibroscope.spectral.welch), the top-level re-export last
    for modname in sorted(MODULES, key=lambda m: (m == "vibroscope", m.count("."), m)):
        mod = MODULES[modname]
        for name in getattr(mod, "__all__", ()):
            obj = getattr(mod, name)
            if not (inspect.isfunction(obj) or inspect.isclass(obj)):
                continue
            if not getattr(obj, "__module__", "").startswith("vibroscope"):
                continue
            found.setdefault(id(obj), (f"{modname}.{name}", obj))
    return dict(sorted(found.values(), key=lambda kv: kv[0]))


def _methods(cls: type) -> Iterator[tuple[str, object]]:
    for name, attr in vars(cls).items():
        if name.startswith("_"):
            continue
        if isinstance(attr, (classmethod, staticmethod)) or inspect.isfunction(attr):
            yield name, getattr(cls, name)


def _parameters(obj: object) -> list[str]:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):  # a signature Python cannot tell: nothing to check
        return []
    return [
        p.name
        for p in sig.parameters.values()
        if p.name not in ("self", "cls")
        and not p.name.startswith("_")  # a private field (a dataclass cache) is not the caller's
        and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    ]


def documented_names(doc: str) -> tuple[set[str], set[str]]:
    """Names listed in the numpydoc parameter-like sections of `doc`, and the sections found.

    Parameters
    ----------
    doc : str
        A docstring, cleaned by :func:`inspect.getdoc` (left margin at column 0).

    Examples
    --------
    >>> names, sections = documented_names("Sum.\\n\\nParameters\\n----------\\nx, y : float\\n    Terms.\\nz\\n")
    >>> sorted(names), sorted(sections)
    (['x', 'y', 'z'], ['Parameters'])
    """
    lines = doc.splitlines()
    names: set[str] = set()
    sections: set[str] = set()
    section = None
    for i, line in enumerate(lines):
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if line.strip() and re.fullmatch(r"\s*-{3,}\s*", nxt):
            section = line.strip()
            sections.add(section)
            continue
        if section not in SECTIONS or re.fullmatch(r"\s*-{3,}\s*", line) or not line or line[0].isspace():
            continue
        m = re.match(r"^(\*{0,2}[A-Za-z_]\w*(?:\s*,\s*\*{0,2}[A-Za-z_]\w*)*)\s*(?::|$)", line)
        if m:
            names |= {n.strip().lstrip("*") for n in m.group(1).split(",")}
    return names, sections


def _cases() -> Iterator[tuple[str, object, list[str], str]]:
    """(public name, object, its parameters, the docstring text they must be found in)."""
    for qualname, obj in _public_objects().items():
        if inspect.isclass(obj):
            doc = inspect.getdoc(obj) or ""
            init = vars(obj).get("__init__")
            init_doc = (inspect.getdoc(init) or "") if init is not None else ""
            if init_doc and init_doc != doc:
                doc = f"{doc}\n\n{init_doc}"
            # exception and Enum constructors are not the author's to document
            params = [] if issubclass(obj, BaseException) or _is_enum(obj) else _parameters(obj)
            yield qualname, obj, params, doc
            for mname, meth in _methods(obj):
                yield f"{qualname}.{mname}", meth, _parameters(meth), inspect.getdoc(meth) or ""
        else:
            yield qualname, obj, _parameters(obj), inspect.getdoc(obj) or ""


def _is_enum(cls: type) -> bool:
    import enum

    return issubclass(cls, enum.Enum)


CASES = list(_cases())


def _params(qualname: str, pname: str | None):
    marks = (
        [pytest.mark.xfail(strict=True, reason="undocumented (see UNDOCUMENTED)")]
        if (qualname, pname) in UNDOCUMENTED
        else []
    )
    return pytest.param(qualname, pname, marks=marks, id=f"{qualname}-{pname or 'docstring'}")


ITEMS = [_params(q, None) for q, _, _, _ in CASES] + [_params(q, p) for q, _, ps, _ in CASES for p in ps]
BY_NAME = {q: (obj, ps, doc) for q, obj, ps, doc in CASES}


def test_every_module_imports():
    """pkgutil reaches every module; only a missing optional extra may keep one out."""
    bad = {m: e for m, e in IMPORT_FAILURES.items() if not any(o in e for o in OPTIONAL)}
    assert not bad, bad
    if IMPORT_FAILURES:
        pytest.skip(f"optional extras missing: {sorted(IMPORT_FAILURES)}")


def test_the_walk_finds_the_public_api():
    """A sanity check on the walk itself: the curated names and every room are in it."""
    names = set(BY_NAME)
    for expected in ("vibroscope.signals.Signals", "vibroscope.spectral.welch", "vibroscope.modal.ssi_cov",
                     "vibroscope.models.LumpedModel", "vibroscope.gap.diagnose", "vibroscope.io.read_mcap"):
        assert expected in names
    assert len(CASES) > 100


def test_undocumented_list_has_no_stale_entries():
    """Every entry of UNDOCUMENTED names a collected object and parameter (strictness both ways)."""
    collected = {(q, None) for q in BY_NAME} | {(q, p) for q, (_, ps, _) in BY_NAME.items() for p in ps}
    assert not sorted(UNDOCUMENTED - collected, key=str)


def missing() -> dict[str, list[str | None]]:
    """Public name -> its gaps: ``None`` when it has no docstring (or, taking parameters, no
    Parameters section; a class may list its fields as Attributes), then each parameter that no
    section lists."""
    out: dict[str, list[str | None]] = {}
    for qualname, obj, params, doc in CASES:
        names, sections = documented_names(doc)
        wanted = {"Parameters", "Attributes"} if inspect.isclass(obj) else {"Parameters"}
        gaps: list[str | None] = [None] if not doc.strip() or (params and not wanted & sections) else []
        gaps += [p for p in params if p not in names]
        if gaps:
            out[qualname] = gaps
    return out


GAPS = missing()


@pytest.mark.parametrize("qualname, pname", ITEMS)
def test_documented(qualname, pname):
    if pname is None:
        assert None not in GAPS.get(qualname, ()), f"{qualname} has no docstring with a Parameters section"
    else:
        assert pname not in GAPS.get(qualname, ()), f"{qualname}: parameter {pname!r} undocumented"


if __name__ == "__main__":  # print UNDOCUMENTED_BY_OBJECT for the current tree
    import textwrap

    print("UNDOCUMENTED_BY_OBJECT: dict[str, tuple[str | None, ...]] = {")
    room = None
    for qualname, gaps in sorted(missing().items()):
        if qualname.split(".")[1] != room:
            room = qualname.split(".")[1]
            print(f"    # vibroscope.{room}")
        items = ", ".join("None" if g is None else f'"{g}"' for g in gaps) + ("," if len(gaps) == 1 else "")
        print(textwrap.fill(f'"{qualname}": ({items}),', 108, initial_indent="    ", subsequent_indent="        ",
                            break_on_hyphens=False, break_long_words=False))
    print("}")
