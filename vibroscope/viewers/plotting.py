"""The default plotting backend (matplotlib) of the results' ``.plot()`` (:mod:`vibroscope._plotting`).

Every figure a result draws of itself, by the name :func:`vibroscope._plotting.draw` asks for; each
loads its module (and matplotlib) on first use. A replacement backend offers the same names with
the same signatures (the result first).
"""

from __future__ import annotations

from vibroscope._lazy import lazy_attributes

_FIGURES = {
    "plot_spectrum": "figures", "plot_frf": "figures", "plot_ods": "figures",
    "plot_mode_shapes": "figures", "plot_mode_set_comparison": "figures",
    "plot_level_evidence": "gap_figures", "plot_gap_report": "gap_figures",
    "plot_hydraulic_comparison": "instruments", "plot_bode": "instruments",
    "plot_nyquist": "instruments", "plot_step": "instruments", "plot_mr_loops": "instruments",
}

__all__ = sorted(_FIGURES)

__getattr__, __dir__ = lazy_attributes(
    __name__, {k: f"vibroscope.viewers.{m}" for k, m in _FIGURES.items()})
