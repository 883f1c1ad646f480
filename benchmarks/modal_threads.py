"""Modal identification on LUMO (18 channels x 1e5 samples) with the BLAS threads as they are.

Issue #9, target 7: SSI-COV on LUMO must take at most 10 s wall with the machine's default
threads; BLAS oversubscription used to swing it from seconds to half a minute on a loaded
machine. vibroscope's identification entry points now run on one BLAS thread
(:func:`vibroscope.modal.automatic.one_blas_thread`). This times the whole
``analyse_signals`` (spectra, band, SSI-COV, bootstrap) with the bound (as shipped) and without
it (the wrapped functions' originals), idle and with ``--load N`` busy processes beside it::

    python benchmarks/modal_threads.py [--shared ../shared/data] [--load 2] [--repeat 2]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time
from pathlib import Path
from unittest import mock

import numpy as np


def _spin() -> None:  # pragma: no cover - a busy process
    while True:
        pass


def _time(sig, bounded: bool, repeat: int) -> tuple[float, np.ndarray]:
    from vibroscope.modal import automatic
    from vibroscope.pipeline import analyse_signals

    patches = [] if bounded else [mock.patch.object(automatic, n, getattr(automatic, n).__wrapped__)
                                  for n in ("auto_ssi", "auto_lscf", "polymax_oma")]
    best, f = np.inf, None
    for p in patches:
        p.start()
    try:
        for _ in range(repeat):
            t = time.perf_counter()
            an = analyse_signals(sig)
            best = min(best, time.perf_counter() - t)
            f = an.modal.natural_frequencies
    finally:
        for p in patches:
            p.stop()
    return best, f


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    ap.add_argument("--load", type=int, default=2, help="busy processes during the loaded runs (default 2)")
    ap.add_argument("--repeat", type=int, default=2, help="runs per case, the best kept (default 2)")
    args = ap.parse_args()
    from vibroscope.io.convert import read_csv

    sig = read_csv(args.shared / "lumo" / "data_lumo.csv", fs=1651.0, columns="0-17")
    print(f"LUMO: {sig.n_channels} channels x {sig.n_samples} samples")
    for load in (0, args.load):
        procs = [mp.Process(target=_spin, daemon=True) for _ in range(load)]
        for p in procs:
            p.start()
        try:
            for bounded in (True, False):
                t, f = _time(sig, bounded, args.repeat)
                print(f"case=modal_lumo  load={load}  blas={'1 thread' if bounded else 'default'}  "
                      f"wall_s={t:.2f}  modes={len(f)} ({', '.join(f'{x:.3f}' for x in f[:5])}...)")
        finally:
            for p in procs:
                p.terminate()


if __name__ == "__main__":
    main()
