"""Mutation campaign for the MCAP reader: cut, flip, zero and re-frame bytes of real and
synthetic logs, and count what the reader makes of them.

For every mutation the damaged copy is scanned (through a reading path drawn at random:
``stream``, ``indexed`` or ``auto``, fast indexing on or off) and compared with the intact
file's messages (channel id, log time, payload):

- *altered*: a returned message that is not one of the original's (must be 0);
- *lost without a report*: messages missing while the scan reported no damage (must be 0);
- *lost from untouched chunks*: messages of chunks no mutated byte touched, missing (0 is
  the goal);
- *other exceptions*: anything but a :class:`~vibroscope.errors.VibroscopeError` (must be 0).

Bytes changed inside a chunk written without a CRC (the large capstan recordings have
none) cannot be detected by any reader: such mutations are counted apart, with the number
of altered messages they return. The synthetic Imu logs are also read with ``read_mcap(..., resample=False)``: every sample
must be one of the originals.

Usage::

    python examples/robustness/mutation_campaign.py --n 2000 --seed 1
"""

from __future__ import annotations

import argparse
import os
import random
import struct
import tempfile
import time
import traceback
from collections import Counter
from pathlib import Path

import numpy as np

from vibroscope.errors import VibroscopeError
from vibroscope.io import read_mcap
from vibroscope.io._scan import scan
from vibroscope.io.mcap_write import write_ros2_mcap
from vibroscope.signals import Signals

CAPSTAN = Path(os.environ.get("VIBROSCOPE_SHARED_DATA", Path(__file__).resolve().parents[2].parent / "shared" / "data")
               ) / "mcap" / "capstan"
IMU_CH = "/imu.linear_acceleration.x"
MODES = [("stream", True), ("stream", False), ("indexed", True), ("auto", True), ("auto", False)]


class Original:
    """An intact log: its bytes, its messages, and the extent and messages of each chunk."""

    def __init__(self, path: Path, imu: np.ndarray | None = None) -> None:
        self.path = path
        self.data = path.read_bytes()
        res = scan(path)
        assert not res.skipped, res.skipped
        self.all = Counter(res.messages())
        self.chunks = []  # (start, end, Counter of messages)
        self.no_crc: list[tuple[int, int]] = []  # extents of the chunks without a CRC-32
        for b in res.blocks:
            if b.file_offset < 0:
                continue
            (length,) = struct.unpack_from("<Q", self.data, b.file_offset + 1)
            one = type(res)(path=path, file_size=0, blocks=[b])
            self.chunks.append((b.file_offset, b.file_offset + 9 + length, Counter(one.messages())))
            (crc,) = struct.unpack_from("<I", self.data, b.file_offset + 9 + 24)
            if crc == 0:  # a chunk written without a CRC: a changed byte inside it cannot be detected
                self.no_crc.append((b.file_offset, b.file_offset + 9 + length))
        self.imu = imu


def mutate(rng: random.Random, data: bytes, chunks: list) -> tuple[bytes, list[tuple[int, int]], str]:
    """A damaged copy, the byte ranges changed ([a, b); a cut is (cut, inf)) and the kind."""
    n = len(data)
    kind = rng.choice(["cut", "flip", "flips", "zero", "frame", "garbage", "chunkzero", "splice"])
    b = bytearray(data)
    if kind == "cut":
        c = rng.randrange(0, n)
        return bytes(b[:c]), [(c, float("inf"))], kind
    if kind == "flip":
        p = rng.randrange(8, n)
        b[p] ^= 1 << rng.randrange(8)
        return bytes(b), [(p, p + 1)], kind
    if kind == "flips":
        ps = [rng.randrange(8, n) for _ in range(rng.randint(2, 16))]
        for p in ps:
            b[p] ^= 1 << rng.randrange(8)
        return bytes(b), [(p, p + 1) for p in ps], kind
    if kind in ("zero", "chunkzero"):
        if kind == "chunkzero" and chunks:
            a, e, _ = rng.choice(chunks)
            a, e = (a, a + 9) if rng.random() < 0.5 else (a, e)
        else:
            a = rng.randrange(8, n)
            e = min(n, a + rng.choice([1, 9, 64, 1000, 20000]))
        b[a:e] = bytes(e - a)
        return bytes(b), [(a, e)], kind
    if kind == "frame":  # a record header's opcode or length rewritten, at a chunk or anywhere
        p = rng.choice([c[0] for c in chunks]) if chunks and rng.random() < 0.7 else rng.randrange(8, n - 9)
        if rng.random() < 0.5:
            b[p] = rng.choice([0x00, 0x05, 0x06, 0x07, 0x0F, 0x10, 0x42, 0x7F, 0x80, 0xFF])
            return bytes(b), [(p, p + 1)], kind
        struct.pack_into("<Q", b, p + 1, rng.choice([0, 1, 2**63, 2**64 - 1, rng.randrange(0, 2 * n)]))
        return bytes(b), [(p + 1, p + 9)], kind
    if kind == "garbage":  # random bytes after the magic (or after a random point)
        a = 8 if rng.random() < 0.3 else rng.randrange(8, n)
        m = rng.choice([9, 100, 5000])
        g = bytes(rng.getrandbits(8) for _ in range(m))
        return bytes(b[:a]) + g + bytes(b[a + m :]), [(a, a + m)], kind
    # splice: a range deleted (everything after it moves: every later chunk is "touched")
    a = rng.randrange(8, n)
    e = min(n, a + rng.choice([1, 7, 300]))
    return bytes(b[:a]) + bytes(b[e:]), [(a, float("inf"))], kind


def main(argv: list[str] | None = None) -> int:
    """Run the campaign; returns 1 when a message was altered or lost without a report, or an
    exception other than VibroscopeError escaped, else 0.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (default ``sys.argv[1:]``): ``--n``, ``--seed``, ``--no-big``.
    """
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=500, help="number of mutations")
    ap.add_argument("--seed", type=int, default=0, help="random seed")
    ap.add_argument("--no-big", action="store_true", help="leave out the capstan files over 1 MB")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="vibroscope-mut-") as d:
        return _campaign(args, Path(d))


def _campaign(args: argparse.Namespace, tmp: Path) -> int:
    rng = random.Random(args.seed)
    originals = []
    for f in sorted(CAPSTAN.glob("*.mcap")) if CAPSTAN.is_dir() else []:
        if not (args.no_big and f.stat().st_size > 1 << 20):
            originals.append(Original(f))
    for comp in ("zstd", "none"):
        x = np.random.default_rng(args.seed).standard_normal((1, 3000))
        p = write_ros2_mcap(tmp / f"imu_{comp}.mcap", Signals(data=x, fs=1000.0, channels=[IMU_CH], t0=10.0),
                            chunk_size=20_000,
                            compression=comp)
        originals.append(Original(p, imu=x[0]))
    weights = [1.0 if len(o.data) < 1 << 20 else 0.15 for o in originals]
    c = Counter()
    kinds = Counter()
    failures: list[str] = []
    t0 = time.time()
    q = tmp / "mutated.mcap"
    for i in range(args.n):
        o = rng.choices(originals, weights)[0]
        bad, ranges, kind = mutate(rng, o.data, o.chunks)
        kinds[kind] += 1
        c["mutations"] += 1
        n_changed = sum(int(min(e, len(o.data)) - a) for a, e in ranges if e != float("inf"))
        c["bytes mutated (flipped, zeroed, rewritten, random)"] += n_changed
        c["bytes cut off or shifted"] += sum(int(len(o.data) - a) for a, e in ranges if e == float("inf"))
        q.write_bytes(bad)
        mode, fast = rng.choice(MODES)
        try:
            res = scan(q, mode=mode, fast=fast)
        except VibroscopeError:
            c["refused (VibroscopeError)"] += 1
            c["faults detected/reported"] += 1
            continue
        except Exception as exc:  # noqa: BLE001 - counted, must be 0
            c["exceptions other than VibroscopeError"] += 1
            failures.append(f"{o.path.name} {kind} {ranges} {mode}: {type(exc).__name__}: {exc}\n"
                            + traceback.format_exc(limit=3))
            continue
        got = Counter(res.messages())
        for a, e, msgs in o.chunks:
            if not any(ra < e and a < rb for ra, rb in ranges):
                lost = sum((msgs - got).values())
                c["messages lost from untouched chunks"] += lost
                if lost:
                    failures.append(f"{o.path.name} {kind} {ranges} {mode}: untouched chunk at {a} lost {lost}")
        if any(ra < e and a < rb for a, e in o.no_crc for ra, rb in ranges):
            # bytes changed inside a chunk written without a CRC: the format gives no means to tell
            c["mutations inside chunks without a CRC (undetectable by the format)"] += 1
            c["  their messages returned altered"] += sum((got - o.all).values())
            continue
        altered = got - o.all
        missing = o.all - got
        c["messages returned"] += sum(got.values())
        c["messages altered"] += sum(altered.values())
        reported = bool(res.damage or res.skipped)
        c["faults detected/reported"] += reported or bool(res.warnings)
        if missing and not reported:
            c["messages lost without a report"] += sum(missing.values())
            failures.append(f"{o.path.name} {kind} {ranges} {mode}: {sum(missing.values())} lost, no report")
        c["messages lost (reported)"] += sum(missing.values()) if reported else 0
        if altered:
            failures.append(f"{o.path.name} {kind} {ranges} {mode}: {sum(altered.values())} altered")
        if o.imu is not None:
            try:
                r = read_mcap(q, [IMU_CH], resample=False)
                c["Imu samples read"] += r.n_samples
                c["Imu samples altered"] += int((~np.isin(r.data[0], o.imu)).sum())
            except VibroscopeError:
                pass
            except Exception as exc:  # noqa: BLE001
                c["exceptions other than VibroscopeError"] += 1
                failures.append(f"read_mcap {kind} {ranges}: {type(exc).__name__}: {exc}")
    print(f"vibroscope MCAP mutation campaign: seed {args.seed}, {time.time() - t0:.1f} s")
    print(f"files tried: {len(originals)} ({', '.join(o.path.name for o in originals)})")
    print("mutations by kind: " + ", ".join(f"{k} {v}" for k, v in sorted(kinds.items())))
    for k in ("mutations", "bytes mutated (flipped, zeroed, rewritten, random)", "bytes cut off or shifted",
              "faults detected/reported", "refused (VibroscopeError)", "messages returned",
              "messages lost (reported)", "messages lost without a report", "messages altered",
              "messages lost from untouched chunks", "Imu samples read", "Imu samples altered",
              "exceptions other than VibroscopeError",
              "mutations inside chunks without a CRC (undetectable by the format)", "  their messages returned altered"):
        print(f"{k}: {c[k]}")
    for f in failures[:20]:
        print("FAILURE:", f)
    bad = c["messages lost without a report"] + c["messages altered"] + c["Imu samples altered"] + \
        c["exceptions other than VibroscopeError"]
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
