"""Sim-to-real gap diagnosis: where a model and a log disagree, which unmodelled effect
explains it, and how far the gap shrinks once that effect is added (held-out data).

Public names (imported lazily, so ``import vibroscope.gap`` stays light):
:func:`diagnose`, :func:`fit_linear_model`, :class:`GapReport`, :data:`EFFECTS`.
"""

from __future__ import annotations

__all__ = ["diagnose", "fit_linear_model", "GapReport", "EFFECTS"]


from vibroscope._lazy import lazy_attributes

__getattr__, __dir__ = lazy_attributes(__name__, {"diagnose": ".diagnosis", "fit_linear_model": ".diagnosis",
                                                  "GapReport": ".report", "EFFECTS": ".report"})
