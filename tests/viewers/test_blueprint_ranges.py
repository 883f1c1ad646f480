"""The blueprint shows whole records and bands, and frames the structure (checked by eye in the
rerun 0.41 viewer; this pins the settings that made it so)."""

from __future__ import annotations

import numpy as np

from vibroscope import Signals
from vibroscope.spectral import csd_matrix, frf
from vibroscope.viewers.rerun_view import log_analysis, read_rrd


def test_time_series_and_spectra_views_span_the_whole_axis(tmp_path):
    rng = np.random.default_rng(0)
    sig = Signals(data=rng.standard_normal((2, 4000)), fs=200.0, channels=["/f.wrench.force.x",
                                                                           "/imu/a.linear_acceleration.x"],
                  units=["N", "m/s^2"])
    G = csd_matrix(sig, nperseg=256)
    h = frf(G, "/f.wrench.force.x")
    path = log_analysis(signals=sig, csd=G.select(["/imu/a.linear_acceleration.x"]), psd=G.psd(), frf=h,
                        rrd_path=tmp_path / "r.rrd")
    bp = read_rrd(path, blueprint=True)
    axes = [v for e, v in bp.items() if e.endswith("/TimeAxis")]
    ranges = [v for e, v in bp.items() if e.endswith("/VisibleTimeRanges")]
    n_series_views = 2 + 2 + 3  # two channels, PSD + singular values, FRF magnitude/phase/coherence
    assert len(axes) == n_series_views and len(ranges) == n_series_views
