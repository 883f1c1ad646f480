"""Viewers: matplotlib figures and rerun recordings of analysis results.

An edge adapter: importing :mod:`vibroscope.viewers` imports neither matplotlib nor rerun; the
functions below load their modules (and those libraries) on first use.

- :mod:`vibroscope.viewers.figures`: :func:`plot_spectrum`, :func:`plot_frf`,
  :func:`plot_mode_shapes`, :func:`plot_singular_values`, :func:`plot_signals`,
  :func:`plot_stabilization`, :func:`plot_frf_synthesis`, :func:`summary_figures` (PNGs).
- :mod:`vibroscope.viewers.rerun_view`: :func:`log_analysis` (one ``.rrd`` recording with a
  blueprint, or a spawned viewer) and :func:`read_rrd` (read one back with rerun's reader).
- :mod:`vibroscope.viewers.acquisition`: :func:`plot_kinematics` (acceleration, velocity and
  displacement versus time), :func:`plot_ods` / :func:`log_ods` (operating deflection shapes, drawn
  and animated like modes).
- :mod:`vibroscope.viewers.gap_figures`: :func:`plot_gap_report` (the figures of a sim-to-real
  gap diagnosis, :class:`vibroscope.gap.report.GapReport`).
- :mod:`vibroscope.viewers.rerun_gap`: :func:`log_gap_report` (a gap diagnosis as one ``.rrd``
  recording with a blueprint).
- :mod:`vibroscope.viewers.instruments`: :func:`plot_bode`, :func:`plot_nyquist`,
  :func:`plot_step`, :func:`plot_mr_loops`, :func:`plot_hydraulic_comparison` (the founding
  paper's instruments).

This package is also the default plotting backend of the results' ``.plot()``
(:mod:`vibroscope._plotting`): every figure a result draws of itself is one of the names below.
"""

from __future__ import annotations

from vibroscope._lazy import lazy_attributes

_LAZY = {
    "plot_spectrum": "figures", "plot_frf": "figures", "plot_mode_shapes": "figures",
    "plot_singular_values": "figures", "plot_signals": "figures", "summary_figures": "figures",
    "log_analysis": "rerun_view", "read_rrd": "rerun_read",
    "plot_gap_report": "gap_figures", "log_gap_report": "rerun_gap",
    "plot_stabilization": "figures", "plot_frf_synthesis": "figures",
    "plot_kinematics": "acquisition", "plot_ods": "figures", "ods_as_modal_model": "acquisition",
    "log_ods": "acquisition", "plot_mode_set_comparison": "figures",
    "plot_level_evidence": "gap_figures", "plot_hydraulic_comparison": "instruments",
    "plot_bode": "instruments", "plot_nyquist": "instruments", "plot_step": "instruments",
    "plot_mr_loops": "instruments",
}

__all__ = sorted(_LAZY)


__getattr__, __dir__ = lazy_attributes(__name__, {k: f".{m}" for k, m in _LAZY.items()})
