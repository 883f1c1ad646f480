"""Scaling curves of the cross-spectral engine (issue #9, target 8): time and memory of
``csd_matrix`` versus record length and versus channel count.

``python benchmarks/scaling.py [--quick] [--out docs/bench/scaling.png] [--json rows.json]``
(``--replot rows.json`` redraws the figure from saved rows).

* time and tracemalloc peak versus record length, 1e5 … 1e7 samples at 10 channels (nperseg 4096,
  50 % overlap, Hann, default threads), with the linear fit ``t0 + b·length``; the
  record itself is not counted (it exists before the call);
* time and peak versus channel count, 1 … 64 channels at a fixed length (1e6; 2e5 with --quick),
  for the full matrix (C(C+1)/2 products per bin) and the reference-channel mode with two
  references (``csd_matrix(..., references=[0, 1])``, C·2 + C products); the peak grows as C²
  because the result itself is ``n_freqs × C × C`` complex (2049 × 64 × 64 × 16 B = 134 MB);
* the memory check of target 2: peak at 1e6 against 1e7 samples (10 channels) and 1e6 against
  1e8 samples (1 channel; 0.8 GB of record), which must agree within 1.2×;
* which contraction: the compiled pair kernel against ``np.matmul`` (batched zgemm, after the
  ``(f, C, segments)`` transpose) on one block of spectra, 4 … 64 channels.

Times are the best of a few runs; every figure should be read as a ratio (shared machine).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
from _timing import best, peak_bytes  # noqa: E402


def _peak_mb(fn) -> float:
    return peak_bytes(fn) / 1e6

KW = dict(fs=1000.0, nperseg=4096, noverlap=2048, window="hann", detrend="constant")


def vs_length(lengths, n_ch=10) -> list[dict]:
    from vibroscope.spectral import csd_matrix

    x = np.random.default_rng(0).standard_normal((n_ch, max(lengths)))
    rows = []
    for n in lengths:
        xs = x[:, :n]
        t = best(lambda: csd_matrix(xs, **KW), 3 if n <= 10**6 else 2)
        t_sum = best(lambda: np.sum(xs), 5)
        rows.append(dict(panel="length", channels=n_ch, samples=n, time_s=t, peak_MB=_peak_mb(lambda: csd_matrix(xs, **KW)),
                         x_read_pass=t / t_sum))
    return rows


def vs_channels(channels, n) -> list[dict]:
    from vibroscope.spectral import csd_matrix

    x = np.random.default_rng(1).standard_normal((max(channels), n))
    rows = []
    for c in channels:
        xs = x[:c]
        t = best(lambda: csd_matrix(xs, **KW), 2)
        row = dict(panel="channels", channels=c, samples=n, time_s=t, peak_MB=_peak_mb(lambda: csd_matrix(xs, **KW)))
        if c > 2:
            row["ref2_time_s"] = best(lambda: csd_matrix(xs, references=[0, 1], **KW), 2)
        rows.append(row)
    return rows


def memory_check(quick: bool) -> list[dict]:
    from vibroscope.spectral import csd_matrix

    rows = []
    cases = [(10, 10**6, 10**7)] + ([] if quick else [(1, 10**6, 10**8)])
    for c, n0, n1 in cases:
        x = np.random.default_rng(2).standard_normal((c, n1))
        p0 = _peak_mb(lambda: csd_matrix(x[:, :n0], **KW))
        p1 = _peak_mb(lambda: csd_matrix(x, **KW))
        rows.append(dict(panel="memory", channels=c, samples=f"{n0:.0e} vs {n1:.0e}", peak_short_MB=p0,
                         peak_long_MB=p1, ratio=p1 / p0))
        del x
    return rows


def contraction(channels) -> list[dict]:
    from vibroscope.spectral import _kernels

    rows = []
    nf, nb = 2049, 16
    rng = np.random.default_rng(3)
    for c in channels:
        X = rng.standard_normal((c, nb, nf)) + 1j * rng.standard_normal((c, nb, nf))
        ii, jj = (a.astype(np.int64) for a in np.triu_indices(c))
        acc = np.zeros((ii.size, 2 * nf))
        tile = _kernels.frequency_tile(ii.size)
        S = np.zeros((nf, c, c), complex)

        def kernel():
            _kernels.accumulate_pairs(X.view(np.float64), ii, jj, acc, tile)

        def blas():
            Xf = np.ascontiguousarray(X.transpose(2, 0, 1))
            S.__iadd__(np.matmul(Xf.conj(), Xf.transpose(0, 2, 1)))

        kernel()
        blas()
        tk, tb = best(kernel, 5), best(blas, 5)
        rows.append(dict(panel="contraction", channels=c, segments=nb, kernel_ms=tk * 1e3, matmul_ms=tb * 1e3,
                         matmul_over_kernel=tb / tk))
    return rows


def figure(rows, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FormatStrFormatter

    L = [r for r in rows if r["panel"] == "length"]
    C = [r for r in rows if r["panel"] == "channels"]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    n = np.array([r["samples"] for r in L], float)
    t = np.array([r["time_s"] for r in L])
    # linear cost model t = t0 + b·n, least squares in relative error (weights 1/t)
    t0, b_n = np.linalg.lstsq(np.c_[np.ones_like(n), n] / t[:, None], np.ones_like(t), rcond=None)[0]
    nn = np.geomspace(n[0], n[-1], 50)
    a.loglog(n, t, "o-", color="C0", label="csd_matrix, 10 channels")
    a.loglog(nn, t0 + b_n * nn, "--", color="0.5",
             label=f"linear fit {t0 * 1e3:.0f} ms + {b_n * 1e9:.0f} ms per 1e6 samples")
    a.set_xlabel("record length [samples per channel]")
    a.set_ylabel("time [s]", color="C0")
    a.set_title("time and memory vs record length\n(nperseg 4096, 50 % overlap, Hann)")
    a.grid(True, which="both", alpha=0.3)
    a2 = a.twinx()
    a2.semilogx(n, [r["peak_MB"] for r in L], "s:", color="C3", label="extra peak memory")
    a2.set_ylabel("tracemalloc peak [MB]", color="C3")
    a2.set_ylim(0, max(60.0, 1.2 * max(r["peak_MB"] for r in L)))
    a2.axhline(50, color="C3", lw=0.8, alpha=0.5)
    a2.text(n[0], 51, "50 MB budget", color="C3", fontsize=8, va="bottom", ha="left")
    h1, l1 = a.get_legend_handles_labels()
    h2, l2 = a2.get_legend_handles_labels()
    a.legend(h1 + h2, l1 + l2, loc="lower right", fontsize=8)
    for ax in (a, b):
        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(FormatStrFormatter(""))

    c = np.array([r["channels"] for r in C], float)
    b.loglog(c, [r["time_s"] for r in C], "o-", color="C0", label="full matrix, C(C+1)/2 pairs")
    cr = [r for r in C if "ref2_time_s" in r]
    b.loglog([r["channels"] for r in cr], [r["ref2_time_s"] for r in cr], "^-", color="C2",
             label="references=[0, 1], 3C pairs")
    tc = np.array([r["time_s"] for r in C])
    b.loglog(c, tc[-1] * (c / c[-1]) ** 2, "--", color="0.5", label="∝ C² (through the last point)")
    b.xaxis.set_major_formatter(FormatStrFormatter("%g"))
    b.set_xlabel("channels C")
    b.set_ylabel("time [s]", color="C0")
    b.set_title(f"time and memory vs channels\n({C[0]['samples']:.0e} samples per channel)".replace("e+0", "e"))
    b.grid(True, which="both", alpha=0.3)
    b2 = b.twinx()
    b2.loglog(c, [r["peak_MB"] for r in C], "s:", color="C3", label="extra peak memory (full)")
    b2.set_ylabel("tracemalloc peak [MB]", color="C3")
    from matplotlib.ticker import FixedLocator, NullFormatter

    b2.yaxis.set_major_locator(FixedLocator([5, 10, 20, 50, 100, 200, 500, 1000]))
    b2.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    b2.yaxis.set_minor_formatter(NullFormatter())
    h1, l1 = b.get_legend_handles_labels()
    h2, l2 = b2.get_legend_handles_labels()
    b.legend(h1 + h2, l1 + l2, loc="upper left", fontsize=8)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="smaller sizes (about a minute)")
    p.add_argument("--out", type=Path, default=REPO / "docs" / "bench" / "scaling.png", help="figure path")
    p.add_argument("--json", type=Path, help="write the rows as JSON")
    p.add_argument("--replot", type=Path, help="only draw the figure from rows saved with --json")
    a = p.parse_args(argv)
    if a.replot:
        figure(json.loads(a.replot.read_text()), a.out)
        print(f"figure: {a.out}")
        return 0
    from vibroscope.spectral import csd_matrix

    csd_matrix(np.zeros((2, 20_000)), **KW)  # compile / load the cached kernels
    lengths = [10**5, 3 * 10**5, 10**6, 3 * 10**6] + ([] if a.quick else [10**7])
    channels = [1, 2, 4, 8, 16, 32, 64]
    rows = vs_length(lengths)
    rows += vs_channels(channels, 2 * 10**5 if a.quick else 10**6)
    rows += memory_check(a.quick)
    rows += contraction([4, 10, 32, 64])
    print(f"# load: {os.getloadavg()}  cores: {os.cpu_count()}")
    for r in rows:
        print("  ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()))
    figure(rows, a.out)
    print(f"figure: {a.out}")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
