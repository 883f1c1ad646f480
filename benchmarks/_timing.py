"""Timing and memory helpers shared by the benchmark scripts (run as ``python benchmarks/X.py``)."""

from __future__ import annotations

import gc
import time
import tracemalloc


def times(fn, repeat: int) -> list[float]:
    """Wall times in s of `repeat` calls of `fn()`, each after a garbage collection."""
    out = []
    for _ in range(repeat):
        gc.collect()
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return out


def best(fn, repeat: int = 3) -> float:
    """Shortest wall time in s of `repeat` calls of `fn()`."""
    return min(times(fn, repeat))


def peak_bytes(fn) -> int:
    """Peak traced memory in bytes (tracemalloc) of one call of `fn()`, above what it started with."""
    gc.collect()
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak
