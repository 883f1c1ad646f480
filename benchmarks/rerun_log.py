"""Logging an analysis to rerun (issue #9, target 6): 1e7 samples and 1000 spectra in <= 2 s, and
the size of the recording, each against baselines measured in the same run::

    python benchmarks/rerun_log.py [--channels 10] [--samples 1000000] [--spectra 1000] [--bins 2049] [--repeat 3]

Cases (best of `--repeat`; each writes a saved ``.rrd`` and includes closing it):

- ``time series``: `--channels` x `--samples` through
  :func:`vibroscope.viewers.rerun_view.log_analysis` as it logs them: one ``send_columns`` per
  channel of the min/max envelope (at most ``MAX_POINTS`` = 1e5 points per channel), and with
  ``max_points=None`` (every sample, one ``send_columns`` per channel);
- ``per-sample rr.log``: the naive way (``set_time`` + ``log(Scalars)`` per sample), timed on
  `--naive` samples and extrapolated to the same number of samples;
- ``spectra``: a :class:`~vibroscope.spectral.Spectrum` of `--spectra` x `--bins` (one
  ``send_columns`` per spectrum, 10 log10 on the frequency timeline);
- ``total``: one ``log_analysis(signals=..., psd=...)`` of both;
- ``live``: the same record streamed block by block (`--block` samples) through
  :class:`vibroscope.viewers.rerun_live.LiveView` to a saved recording (time series as they
  arrive, PSD/FRF/coherence refreshed every 10 blocks, nperseg 4096, first channel the input),
  against ``csd_matrix`` + ``frf`` of the whole record in memory;
- baseline ``np.save``: one write pass of the same float64 samples and spectra to a ``.npy``.

The sizes of the recordings (MB) are printed beside the times.
"""

from __future__ import annotations

import argparse
import sys
import os
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import best  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--channels", type=int, default=10)
    ap.add_argument("--samples", type=int, default=1_000_000, help="per channel")
    ap.add_argument("--spectra", type=int, default=1000)
    ap.add_argument("--bins", type=int, default=2049)
    ap.add_argument("--naive", type=int, default=20_000, help="samples timed with per-sample rr.log")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--block", type=int, default=10_000, help="samples per block of the live case (0: skip it)")
    args = ap.parse_args()

    import rerun as rr

    from vibroscope.signals import Signals
    from vibroscope.spectral._results import Spectrum
    from vibroscope.viewers.rerun_view import MAX_POINTS, log_analysis

    rng = np.random.default_rng(0)
    fs = 1000.0
    sig = Signals(data=rng.standard_normal((args.channels, args.samples)), fs=fs,
                  channels=[f"/imu/s{k}.linear_acceleration.z" for k in range(args.channels)],
                  units=["m/s^2"] * args.channels)
    f = np.linspace(0.0, fs / 2, args.bins)
    psd = Spectrum(frequencies=f, values=rng.random((args.spectra, args.bins)) + 1e-3,
                   channels=[f"/fleet/log{k:04d}.z" for k in range(args.spectra)],
                   units=["m^2/s^4/Hz"] * args.spectra, scaling="density", settings={"fs": fs})
    n_total = args.channels * args.samples
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        npy = d / "x.npy"

        def save_np():
            with open(npy, "wb") as fh:
                np.save(fh, sig.data)
                np.save(fh, psd.values)
                fh.flush()
                os.fsync(fh.fileno())

        base = best(save_np, args.repeat)
        print(f"case=rerun_log  baseline np.save ({n_total:.0e} samples + {args.spectra}x{args.bins} spectra, "
              f"{os.path.getsize(npy) / 1e6:.1f} MB)  best_s={base:.3f}")

        def naive():
            rec = rr.RecordingStream("bench-naive")
            rec.save(str(d / "naive.rrd"))
            x = sig.data[0, : args.naive]
            for i in range(x.size):
                rec.set_time("time", duration=i / fs)
                rec.log("/signals/x", rr.Scalars(x[i]))
            rec.flush()
            rec.disconnect()

        t_naive = best(naive, 1) * n_total / args.naive
        print(f"case=rerun_log  per-sample rr.log, {n_total:.0e} samples (extrapolated from {args.naive})  "
              f"est_s={t_naive:.1f}  ratio_to_np_save={t_naive / base:.0f}x")

        cases = [
            (f"time series {args.channels}x{args.samples}, every sample (max_points=None)",
             dict(signals=sig, max_points=None), "full.rrd"),
            (f"time series {args.channels}x{args.samples}, min/max envelope (max_points={MAX_POINTS})",
             dict(signals=sig), "env.rrd"),
            (f"spectra {args.spectra}x{args.bins}", dict(psd=psd), "spectra.rrd"),
            ("total: time series (envelope) + spectra", dict(signals=sig, psd=psd), "total.rrd"),
        ]
        for name, kw, fn in cases:
            t = best(lambda: log_analysis(rrd_path=d / fn, **kw), args.repeat)
            size = os.path.getsize(d / fn) / 1e6
            print(f"case=rerun_log  {name}  best_s={t:.3f}  ratio_to_np_save={t / base:.1f}x  rrd_MB={size:.1f}")

        if args.block:
            from vibroscope.spectral import csd_matrix, frf
            from vibroscope.viewers.rerun_live import record_blocks, stream_blocks

            def offline():
                frf(csd_matrix(sig, nperseg=4096), sig.channels[0])

            def live():
                rec = rr.RecordingStream("bench-live")
                rec.save(str(d / "live.rrd"))
                view = stream_blocks(record_blocks(sig, args.block), rec, input=sig.channels[0], nperseg=4096,
                                     every_blocks=10, every_s=None)
                rec.flush()
                rec.disconnect()
                live.refreshes = len(view.refreshes)

            t_off = best(offline, 1)
            t_live = best(live, 1)
            print(f"case=rerun_log  offline csd_matrix + frf (no logging)  best_s={t_off:.3f}")
            print(f"case=rerun_log  live: {args.samples // args.block} blocks of {args.block}, {live.refreshes} "
                  f"refreshes  best_s={t_live:.3f}  ratio_to_offline={t_live / t_off:.1f}x  "
                  f"rrd_MB={os.path.getsize(d / 'live.rrd') / 1e6:.1f}")


if __name__ == "__main__":
    main()
