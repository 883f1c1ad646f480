"""The blueprint of an analysis recording: one tab per timeline's views (time series, velocity and
displacement, spectra, FRF, stabilization, mode shapes) and the time panel it starts on.

rerun is imported inside the functions: importing this module never imports it.
"""

from __future__ import annotations

import numpy as np

from vibroscope.viewers.rerun_paths import channel_entity, mode_entity

__all__ = ["build_blueprint", "whole_time_axis"]


def whole_time_axis(rrb, timeline: str, start: dict, end: dict):
    """The x axis of a time-series view showing [start, end] of `timeline` and every datum of it.

    Without it a view shows a window around the time cursor; with it, the whole record (or band).

    Parameters
    ----------
    rrb : module
        :mod:`rerun.blueprint` (imported by the caller).
    timeline : str
        The timeline the view plots against, e.g. ``"time"``, ``"frequency_mHz"``.
    start, end : dict
        Keyword arguments of :meth:`rerun.blueprint.TimeRangeBoundary.absolute` for the ends of
        the axis, e.g. ``dict(seconds=0.0)`` or ``dict(seq=1000)``.

    Returns
    -------
    dict
        ``axis_x`` and ``time_ranges``, keyword arguments of :class:`rerun.blueprint.TimeSeriesView`.
    """
    axis = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.absolute(**start),
                                                 end=rrb.TimeRangeBoundary.absolute(**end)))
    ranges = rrb.VisibleTimeRange(timeline, start=rrb.TimeRangeBoundary.infinite(),
                                  end=rrb.TimeRangeBoundary.infinite())
    return dict(axis_x=axis, time_ranges=ranges)


def _eye(rrb, positions: np.ndarray):
    """A camera that frames the whole structure from the side, slightly above, z up."""
    pos = np.asarray(positions, dtype=float).reshape(-1, 3)
    target = pos.mean(axis=0) if pos.size else np.zeros(3)
    ptp = np.ptp(pos, axis=0) if len(pos) > 1 else np.ones(3)
    ext = float(ptp.max()) or 1.0
    tall = int(np.argmax(ptp)) == 2  # a tower: narrow tall views; else a beam or chain: wide views
    d = np.array([1.0, -1.0, 0.3]) if tall else np.array([0.1, -1.0, 0.35])
    eye = target + (1.6 if tall else 0.8) * ext * d / np.linalg.norm(d)
    return rrb.EyeControls3D(position=eye.tolist(), look_target=target.tolist(), eye_up=[0.0, 0.0, 1.0])


def build_blueprint(*, signals, spec_entities, frf_present, csd_present, modal, ftl, f_range=None,
                    positions=None, stabilization_present=False, kinematics=None):
    """The blueprint of an analysis recording (:func:`vibroscope.viewers.rerun_view.log_analysis`).

    One tab per group of views, each named with the timeline its views need: time series,
    velocity and displacement, spectra (PSD, CSD singular values), FRF (magnitude, phase,
    coherence), stabilization diagram, mode shapes (a 3-D view per mode beside the mode table),
    and the recording's description. The time panel starts on ``animation`` (playing, looped)
    with modes, else on ``time`` with time series, else on the frequency timeline.

    Parameters
    ----------
    signals : Signals or None
        The time series logged under ``/signals`` (one view per channel).
    spec_entities : bool
        Whether PSDs are logged under ``/psd``.
    frf_present : bool
        Whether FRFs are logged under ``/frf``.
    csd_present : bool
        Whether the CSD's singular values are logged under ``/csd/singular_values``.
    modal : ModalModel or None
        The modes (one 3-D view each, named with frequency and damping).
    ftl : str
        The frequency timeline (``"frequency_mHz"`` or ``"frequency_uHz"``).
    f_range : tuple of int, optional
        First and last index of the frequency timeline shown by the spectral views; default the
        views' own range.
    positions : ndarray, shape (n_points, 3), optional
        Sensor positions in m, to place the 3-D views' camera.
    stabilization_present : bool, optional
        Whether a stabilization diagram is logged under ``/stabilization``.
    kinematics : (Signals, Signals), optional
        Velocity and displacement logged under ``/velocity`` and ``/displacement``.

    Returns
    -------
    rerun.blueprint.Blueprint
    """
    import rerun.blueprint as rrb

    tabs = []
    active = None
    fx = {} if f_range is None else whole_time_axis(rrb, ftl, dict(seq=int(f_range[0])), dict(seq=int(f_range[1])))
    # resonances sit low in the band: keep the legends out of their way
    legend = rrb.PlotLegend(corner=rrb.Corner2D.RightTop)
    if signals is not None:
        tx = whole_time_axis(rrb, "time", dict(seconds=0.0), dict(seconds=float(signals.duration)))
        views = [rrb.TimeSeriesView(origin=channel_entity("signals", c), name=f"{c} [{u or '-'}]", **tx)
                 for c, u in zip(signals.channels, signals.units)]
        tabs.append(rrb.Grid(*views, grid_columns=1 if len(views) <= 4 else 2,
                             name="Time series (timeline: time)"))
    if kinematics is not None:
        vel, disp = kinematics
        tx = whole_time_axis(rrb, "time", dict(seconds=0.0), dict(seconds=float(vel.duration)))
        fc = vel.meta.get("integration", {}).get("f_cut_hz")
        cut = f", high-pass {fc:.3g} Hz" if fc else ""
        tabs.append(rrb.Vertical(
            rrb.TimeSeriesView(origin="/velocity", name=f"velocity [{vel.units[0] or '-'}] (integrated{cut})",
                               plot_legend=legend, **tx),
            rrb.TimeSeriesView(origin="/displacement", name=f"displacement [{disp.units[0] or '-'}] (integrated{cut})",
                               plot_legend=legend, **tx),
            name="Velocity & displacement (timeline: time)"))
    if spec_entities:
        views = [rrb.TimeSeriesView(origin="/psd", name=f"PSD [dB re 1 unit²/Hz] vs frequency ({ftl})",
                                    plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop,
                                                               visible=len(signals.channels) <= 8 if signals
                                                               else True), **fx)]
        if csd_present:
            views.append(rrb.TimeSeriesView(origin="/csd/singular_values",
                                            name=f"CSD singular values (FDD) [dB] vs frequency ({ftl})",
                                            plot_legend=legend, **fx))
        tabs.append(rrb.Vertical(*views, name=f"Spectra (timeline: {ftl})"))
    if frf_present:
        tabs.append(rrb.Vertical(
            rrb.TimeSeriesView(origin="/frf/magnitude_db", name=f"FRF magnitude [dB] vs frequency ({ftl})",
                               plot_legend=legend, **fx),
            rrb.TimeSeriesView(origin="/frf/phase_deg", name=f"FRF phase [deg] vs frequency ({ftl})",
                               axis_y=rrb.ScalarAxis(range=(-180.0, 180.0)), plot_legend=legend, **fx),
            rrb.TimeSeriesView(origin="/frf/coherence", name=f"coherence γ² [-] vs frequency ({ftl})",
                               axis_y=rrb.ScalarAxis(range=(0.0, 1.05)), plot_legend=legend, **fx),
            row_shares=[2, 1.3, 1], name=f"FRF (timeline: {ftl})"))
    if stabilization_present:
        tabs.append(rrb.TimeSeriesView(origin="/stabilization", name=f"Stabilization diagram: model order vs "
                                       f"frequency ({ftl}); green = stable in f, ζ and MAC",
                                       plot_legend=rrb.PlotLegend(visible=False), **fx))
    if modal is not None and len(np.atleast_1d(modal.natural_frequencies)):
        fn = np.asarray(modal.natural_frequencies, dtype=float)
        z = np.asarray(modal.damping_ratios, dtype=float)
        eye = _eye(rrb, positions) if positions is not None else None
        views3d = [rrb.Spatial3DView(origin=mode_entity(r, fn[r]), line_grid=rrb.LineGrid3D(visible=False),
                                     eye_controls=eye,
                                     name=f"{r + 1}: {fn[r]:.4g} Hz, " + (f"{100 * z[r]:.2f} %" if np.isfinite(z[r])
                                                                         else "ζ n/a"))
                   for r in range(fn.size)]
        # tall views side by side for a tower (extent along z), wide views stacked for a beam or chain
        tall = positions is not None and len(positions) > 1 and int(np.argmax(np.ptp(positions, axis=0))) == 2
        tabs.append(rrb.Horizontal(
            rrb.Grid(*views3d, grid_columns=min(8, len(views3d)) if tall else 1),
            rrb.TextDocumentView(origin="/modes/table", name="Mode table"),
            column_shares=[3, 1], name="Mode shapes (timeline: animation)"))
        active = len(tabs) - 1
    tabs.append(rrb.TextDocumentView(origin="/about", name="About this recording"))
    if active is not None:
        panel = rrb.TimePanel(timeline="animation", play_state="playing", loop_mode="all", fps=20.0)
    elif signals is not None:
        panel = rrb.TimePanel(timeline="time")
    else:
        panel = rrb.TimePanel(timeline=ftl)
        active = 0
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=active or 0), panel, collapse_panels=False)
