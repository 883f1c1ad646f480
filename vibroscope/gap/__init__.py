"""Sim-to-real gap diagnosis: where a model and a log disagree, which unmodelled effect
explains it, and how far the gap shrinks once that effect is added (held-out data).

Public names (imported lazily, so ``import vibroscope.gap`` stays light):
:func:`diagnose`, :func:`fit_linear_model`, :class:`GapReport`, :data:`EFFECTS`.
"""

from __future__ import annotations

__all__ = ["diagnose", "fit_linear_model", "GapReport", "EFFECTS"]


def __getattr__(name):
    if name in ("diagnose", "fit_linear_model"):
        import importlib

        return getattr(importlib.import_module("vibroscope.gap.diagnosis"), name)
    if name in ("GapReport", "EFFECTS"):
        import importlib

        return getattr(importlib.import_module("vibroscope.gap.report"), name)
    raise AttributeError(f"module 'vibroscope.gap' has no attribute {name!r}")
