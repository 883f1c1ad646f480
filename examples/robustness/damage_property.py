"""The damage property of the MCAP reader, over damaged variants of the shared logs (issue 21).

Property: for every damaged variant of a log, every value :func:`vibroscope.io.read_mcap` returns
equals the value of the undamaged log at the same stamp, or is NaN; and every loss is counted.

Logs: the five capstan ROS 2 recordings of ``../shared/data/mcap/capstan`` (MIT, from the PyPI
package mcap-bag-parser 0.3.1), one channel each, and a synthetic 1 kHz Imu log (a ±1 signal) written
here. Damage classes (``CLASSES``):

``truncate``        the file cut at a random byte (past the first 10 %);
``bitflip``         1 to 8 random bits flipped after the magic;
``zero4k``          one 4 KiB-aligned block of 4 KiB zeroed;
``delete_chunk``    one chunk record (with the message indexes after it) removed;
``delete_first_chunk`` the first chunk so removed (the issue's worst case: every later offset shifts);
``nudge``           one message of the channel read: its header stamp moved by 0.2 periods to just
                    below the outlier threshold (the larger of 1000 periods and 1 s: below both);
``nanosec``         one message's ``header.stamp.nanosec`` set to a value of 1e9 or more;
``shift_summary``   1 to 4096 bytes inserted after the header record: the summary's offsets all
                    point that far before the records they name;
``lying_size``      one chunk's ``uncompressed_size`` (or one record's length) replaced by a wrong one.

The stamp classes (``nudge``, ``nanosec``) change bytes inside a message, which needs an uncompressed
chunk: they damage an uncompressed copy of the log (same messages, rewritten once by the ``mcap``
writer, without compression; the chunk CRC of the patched chunk set to 0, "not computed"), and only
logs whose channel is read on header stamps (not bagfile_0, whose joint-state stamps are all 0); the
other classes damage the shared file itself. The reference is the undamaged file that was damaged.

Checks of one variant, read with the reference's rate (``read_mcap(variant, channels, fs=ref.fs)``):

- ``ok``: every value is NaN, or equals the reference's value at the same grid time, or (a topic the
  reader interpolates in the undamaged log too: stamps with jitter) lies between the two undamaged
  samples around its time (an on-grid topic is never interpolated: one wrong stamp must not make it
  so); and when samples
  the reference has are missing, the read reports something (``meta`` ``skipped``, ``gaps`` or
  ``outliers``), and the NaN samples are those of the reported gaps;
- ``refused``: a :class:`~vibroscope.errors.VibroscopeError` naming damage (a byte offset,
  "damage", "truncat", "CRC", ...) — the loss of everything, said;
- failures: ``bad_value`` (a value neither NaN nor the undamaged one nor between its neighbours),
  ``silent_loss`` (samples gone, nothing reported; or NaN outside the reported gaps),
  ``lost_unsaid`` (a refusal that names no damage, e.g. "no such topic"), ``crash`` (any other
  exception).

Writes ``damage_property.csv`` (one row per variant), ``damage_property.md`` (pass rate per class)
and ``damage_property.png`` (the same, a bar per class) into ``--out``.

Usage::

    python examples/robustness/damage_property.py --n 48 --seed 1 --out /tmp/dp
    nice -n 10 python examples/robustness/damage_property.py --n 560 --seed 2 --out /tmp/dp560
"""

from __future__ import annotations

import argparse
import csv
import os
import random
import struct
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vibroscope.errors import VibroscopeError
from vibroscope.io import read_mcap
from vibroscope.io.log_index import LogIndex
from vibroscope.io.paths import get_field
from vibroscope.io.timebase import ON_GRID_TOL

SHARED = Path(os.environ.get("VIBROSCOPE_SHARED_DATA", Path(__file__).resolve().parents[2].parent / "shared" / "data"))
CAPSTAN = SHARED / "mcap" / "capstan"
JS = "/robot/joint_state.position[0]"
#: log name -> (file name in CAPSTAN, or None for the synthetic Imu log; channel read)
LOGS = {
    "controlled": ("controlled_data_0.mcap", JS),
    "uncontrolled": ("uncontrolled_data_0.mcap", JS),
    "bagfile": ("bagfile_0.mcap", JS),
    "alternate": ("alternate_bagfile_0.mcap", JS),
    "torque_ripple": ("torque_ripple_data_0.mcap", "/robot/joint_state.effort[0]"),
    "synthetic_imu": (None, "/imu.linear_acceleration.x"),
}
CLASSES = ["truncate", "bitflip", "zero4k", "delete_chunk", "delete_first_chunk", "nudge", "nanosec", "shift_summary",
           "lying_size"]
STAMP_CLASSES = {"nudge", "nanosec"}
MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_CHUNK, OP_MESSAGE_INDEX, OP_DATA_END = 0x01, 0x02, 0x06, 0x07, 0x0F
OUTCOMES = ["ok", "refused", "bad_value", "silent_loss", "lost_unsaid", "crash"]
PASS = {"ok", "refused"}
DAMAGE_WORDS = ("offset", "damag", "truncat", "crc", "corrupt", "invalid", "skipped", "lost", "cut")


# -- the logs ---------------------------------------------------------------------------------------

def records(data: bytes) -> list[tuple[int, int, int]]:
    """(opcode, start, end) of the top-level records after the magic, up to the footer or the first
    record that does not fit."""
    out, p, n = [], len(MAGIC), len(data)
    while p + 9 <= n:
        op = data[p]
        (ln,) = struct.unpack_from("<Q", data, p + 1)
        e = p + 9 + ln
        if e > n:
            break
        out.append((op, p, e))
        if op == OP_FOOTER:
            break
        p = e
    return out


def chunk_records(data: bytes, start: int, end: int) -> list[tuple[int, int, int]]:
    """(opcode, start, end) of the records inside an uncompressed chunk at file offset `start`."""
    body = start + 9
    (slen,) = struct.unpack_from("<I", data, body + 28)  # after start, end times, size, crc
    comp = data[body + 32 : body + 32 + slen]
    if comp:
        return []
    p = body + 32 + slen + 8
    out = []
    while p + 9 <= end:
        (ln,) = struct.unpack_from("<Q", data, p + 1)
        out.append((data[p], p, p + 9 + ln))
        p += 9 + ln
    return out


def write_synthetic_imu(path: Path, n: int = 20_000) -> Path:
    """A 1 kHz Imu log of a ±1 signal (two sines of 0.5), stamps on the grid, zstd chunks of 64 kB."""
    from vibroscope.io.mcap_write import write_ros2_mcap
    from vibroscope.signals import Signals

    k = np.arange(n)
    x = 0.5 * np.sin(2 * np.pi * 37.0 * k / 1000.0) + 0.5 * np.sin(2 * np.pi * 211.0 * k / 1000.0)
    return write_ros2_mcap(path, Signals(data=x[None, :], fs=1000.0, channels=[LOGS["synthetic_imu"][1]], t0=1.7e9),
                           chunk_size=1 << 16, compression="zstd")


def uncompressed_copy(src: Path, dst: Path) -> Path:
    """The same messages (channels, schemas, log and publish times, payloads) rewritten without
    compression by the ``mcap`` writer, chunks of 256 kB, with CRCs."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with open(src, "rb") as fi, open(dst, "wb") as fo:
        r = make_reader(fi)
        head = r.get_header()
        w = Writer(fo, chunk_size=1 << 18, compression=CompressionType.NONE)
        w.start(profile=head.profile, library=head.library)
        schemas, chans = {}, {}
        for sch, ch, m in r.iter_messages(log_time_order=False):
            if ch.id not in chans:
                sid = 0
                if sch is not None:
                    if sch.id not in schemas:
                        schemas[sch.id] = w.register_schema(sch.name, sch.encoding, sch.data)
                    sid = schemas[sch.id]
                chans[ch.id] = w.register_channel(ch.topic, ch.message_encoding, sid, ch.metadata)
            w.add_message(chans[ch.id], m.log_time, m.data, m.publish_time, m.sequence)
        w.finish()
    return dst


@dataclass
class Base:
    """One file that variants are made of: its bytes, records, and the reference read."""

    name: str
    path: Path
    channel: str
    data: bytes = b""
    recs: list = field(default_factory=list)
    ref: object = None
    raw: dict = field(default_factory=dict)  # source -> (stamps ns sorted, values)

    def load(self) -> "Base":
        self.data = self.path.read_bytes()
        self.recs = records(self.data)
        self.ref = read_mcap(self.path, [self.channel])
        return self

    @property
    def chunks(self) -> list[tuple[int, int, int]]:
        return [r for r in self.recs if r[0] == OP_CHUNK]

    def raw_samples(self, source: str) -> tuple[np.ndarray, np.ndarray]:
        """(stamps ns increasing, values) of the channel as logged, on `source` (header.stamp or log_time)."""
        if source not in self.raw:
            log = LogIndex.open(self.path)
            mp = log.topic_of(self.channel)
            cid = log.by_topic[mp.topic][0]
            dec, _ = log.decoders.get(log.scan.channels[cid], log.schema(cid))
            lt = log.log_times(cid)
            st, vals = [], []
            for i, (_off, p) in enumerate(log.payloads(cid)):
                msg = dec(bytes(p))
                if source == "header.stamp":
                    s = get_field(msg, ("header", "stamp"))
                    st.append(int(s.sec) * 1_000_000_000 + int(s.nanosec))
                else:
                    st.append(int(lt[i]))
                vals.append(float(get_field(msg, mp.fields)))
            st, vals = np.asarray(st, np.int64), np.asarray(vals)
            o = np.argsort(st, kind="stable")
            self.raw[source] = (st[o], vals[o])
        return self.raw[source]

    def channel_messages(self) -> list[tuple[int, int]]:
        """(payload start, payload end, log time ns) of the channel's messages (uncompressed chunks)."""
        log = LogIndex.open(self.path)
        cid = log.by_topic[log.topic_of(self.channel).topic][0]
        out = []
        for _op, a, e in self.chunks:
            for op, ra, re in chunk_records(self.data, a, e):
                if op == 0x05 and struct.unpack_from("<H", self.data, ra + 9)[0] == cid:
                    (lt,) = struct.unpack_from("<Q", self.data, ra + 9 + 6)
                    out.append((ra + 9 + 2 + 4 + 8 + 8, re, lt))
        return out


# -- damage -----------------------------------------------------------------------------------------

def _stamp_at(data: bytes, a: int, e: int, log_time: int) -> int | None:
    """File offset of the header stamp (int32 sec, uint32 nanosec) in the CDR payload [a, e): after the
    4-byte encapsulation header, or after a uint32 ``seq`` (capstan's header), whichever holds a time
    within a day of the message's log time (None: no usable stamp, e.g. stamps all 0)."""
    for k in (4, 8):
        if a + k + 8 <= e:
            sec, ns = struct.unpack_from("<iI", data, a + k)
            if abs(sec - log_time * 1e-9) < 86_400 and ns < 1_000_000_000:
                return a + k
    return None


def _zero_chunk_crc(b: bytearray, chunks: list, pos: int) -> None:
    """Set the CRC of the chunk holding byte `pos` to 0 ("not computed"), and the data section CRC."""
    for _op, a, e in chunks:
        if a <= pos < e:
            struct.pack_into("<I", b, a + 9 + 24, 0)
    for op, a, _e in records(bytes(b)):
        if op == OP_DATA_END:
            struct.pack_into("<I", b, a + 9, 0)


def damage(kind: str, rng: random.Random, base: Base) -> tuple[bytes, str]:
    """A damaged copy of `base` of class `kind`, and a one-line description."""
    d, n = base.data, len(base.data)
    b = bytearray(d)
    chunks = base.chunks
    if kind == "truncate":
        c = rng.randrange(n // 10, n)
        return d[:c], f"cut at {c} of {n}"
    if kind == "bitflip":
        k = rng.randint(1, 8)
        where = sorted(rng.randrange(8, n) for _ in range(k))
        for p in where:
            b[p] ^= 1 << rng.randrange(8)
        return bytes(b), f"{k} bits at {' '.join(map(str, where[:4]))}"
    if kind == "zero4k":
        a = rng.randrange(1, max(2, n // 4096)) * 4096
        b[a : a + 4096] = bytes(len(b[a : a + 4096]))
        return bytes(b), f"zeroed {a}..{a + 4096}"
    if kind in ("delete_chunk", "delete_first_chunk"):
        i = 0 if kind == "delete_first_chunk" else rng.randrange(len(chunks))
        _op, a, e = chunks[i]
        recs = base.recs
        j = recs.index(chunks[i]) + 1
        while j < len(recs) and recs[j][0] == OP_MESSAGE_INDEX:
            e = recs[j][2]
            j += 1
        return d[:a] + d[e:], f"chunk {i + 1}/{len(chunks)} at {a} ({e - a} bytes) removed"
    if kind in STAMP_CLASSES:
        msgs = base.channel_messages()
        rng.shuffle(msgs)
        for a, e, lt in msgs:
            p = _stamp_at(d, a, e, lt)
            if p is None:
                continue
            sec, ns = struct.unpack_from("<iI", d, p)
            if kind == "nanosec":
                new = rng.choice([1_000_000_000 + ns % 1000, ns | 0x80000000, ns + 1_000_000_000 * rng.randint(1, 3),
                                  rng.randrange(1_000_000_000, 1 << 32)])
                new = min(new, (1 << 32) - 1)
                struct.pack_into("<I", b, p + 4, new)
                desc = f"nanosec {ns} -> {new} at {p + 4}"
            else:
                tb = base.ref.meta["timebase"][base.channel.split(".")[0]]
                per = 1.0 / tb["fs_est"] if np.isfinite(tb["fs_est"]) else 0.01
                thr = min(1000.0 * per, 1.0)  # the outlier threshold is the larger; stay below both
                delta = rng.choice([-1, 1]) * rng.uniform(0.2 * per, 0.999 * thr)
                t = sec * 1_000_000_000 + ns + int(delta * 1e9)
                struct.pack_into("<iI", b, p, t // 1_000_000_000, t % 1_000_000_000)
                desc = f"stamp moved by {delta:+.6g} s ({delta / per:+.4g} periods) at {p}"
            _zero_chunk_crc(b, chunks, p)
            return bytes(b), desc
        return d, "no header stamp in the channel's messages: undamaged"
    if kind == "shift_summary":
        hdr = base.recs[0]
        k = rng.randint(1, 4096)
        junk = bytes(rng.randrange(256) for _ in range(k))
        return d[: hdr[2]] + junk + d[hdr[2] :], f"{k} bytes inserted at {hdr[2]}"
    if kind == "lying_size":
        if rng.random() < 0.7 and chunks:
            _op, a, e = rng.choice(chunks)
            size = rng.choice([(1 << 32) - 1, (1 << 40), 0, (e - a) * 50, rng.randrange(1, e - a)])
            struct.pack_into("<Q", b, a + 9 + 16, size)
            return bytes(b), f"chunk at {a}: uncompressed_size -> {size}"
        _op, a, e = rng.choice(base.recs[1:-1] or base.recs)
        ln = rng.choice([(1 << 32) - 1, (1 << 63), 2 * n, rng.randrange(0, e - a)])
        struct.pack_into("<Q", b, a + 1, ln)
        return bytes(b), f"record at {a} (opcode {d[a]:#x}): length -> {ln}"
    raise ValueError(f"{kind=} is not one of {CLASSES}")


# -- the property -----------------------------------------------------------------------------------

def check(base: Base, variant: Path) -> tuple[str, str]:
    """(outcome, detail) of reading `variant` against `base`'s reference (see the module notes)."""
    ref = base.ref
    topic = base.channel.split(".")[0]
    try:
        got = read_mcap(variant, [base.channel], fs=ref.fs)
    except VibroscopeError as exc:
        msg = str(exc)
        said = any(w in msg.lower() for w in DAMAGE_WORDS)
        return ("refused" if said else "lost_unsaid"), f"{type(exc).__name__}: {msg[:160]}"
    except Exception as exc:  # noqa: BLE001 - the campaign counts it
        return "crash", f"{type(exc).__name__}: {exc} | {traceback.format_exc(limit=3)[-300:]}"
    fs = ref.fs
    rt = ref.meta["t0_ns"] + np.round(np.arange(ref.n_samples) / fs * 1e9).astype(np.int64)
    gt = got.meta["t0_ns"] + np.round(np.arange(got.n_samples) / fs * 1e9).astype(np.int64)
    rv, gv = ref.data[0], got.data[0]
    # the reference grid sample at each damaged grid time: the same stamp within the reader's on-grid
    # tolerance (1 % of a period: a grid that starts at a later message of a topic with a few µs of jitter)
    k = np.rint((gt - ref.meta["t0_ns"]) * 1e-9 * fs).astype(np.int64)
    inside = (k >= 0) & (k < rt.size)
    same_t = np.zeros(gt.size, bool)
    same_t[inside] = np.abs(rt[k[inside]] - gt[inside]) <= ON_GRID_TOL * 1e9 / fs
    fin = np.isfinite(gv)
    equal = np.zeros(gt.size, bool)
    equal[same_t] = gv[same_t] == rv[k[same_t]]
    bad = fin & ~equal
    interp = 0
    if bad.any() and ref.meta["timebase"][topic]["resampled"]:  # the undamaged log needs interpolation too
        st, sv = base.raw_samples(ref.meta["timebase"][topic]["time_source"])
        j = np.searchsorted(st, gt[bad], "right")
        ok = (j > 0) & (j < st.size)
        lo = np.full(j.size, np.inf)
        hi = np.full(j.size, -np.inf)
        lo[ok] = np.minimum(sv[j[ok] - 1], sv[j[ok]])
        hi[ok] = np.maximum(sv[j[ok] - 1], sv[j[ok]])
        v = gv[bad]
        within = (v >= lo - 1e-12 * np.abs(lo)) & (v <= hi + 1e-12 * np.abs(hi))
        interp = int(within.sum())
        idx = np.flatnonzero(bad)
        bad[idx[within]] = False
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        refv = rv[k[i]] if same_t[i] else float("nan")
        return "bad_value", (f"{int(bad.sum())} of {gt.size} values neither NaN nor the undamaged ones (first at "
                             f"{(gt[i] - rt[0]) * 1e-9:.4f} s: {gv[i]:.6g}, undamaged {refv:.6g})")
    # losses: reference samples with no finite damaged sample at their time
    have = np.zeros(rt.size, bool)
    have[k[same_t & fin]] = True
    lost = int(np.count_nonzero(np.isfinite(rv) & ~have))
    m = got.meta
    nan_here = int(np.count_nonzero(~fin))
    in_gaps = sum(g["n_samples"] for g in m["gaps"] if g["topic"] == topic)
    reported = bool(m["skipped"] or m["gaps"] or m["outliers"])
    if nan_here != in_gaps:
        return "silent_loss", f"{nan_here} NaN samples but {in_gaps} in the reported gaps"
    if lost and not reported:
        return "silent_loss", f"{lost} of {int(np.isfinite(rv).sum())} samples lost, nothing reported"
    return "ok", f"lost {lost}; interpolated within neighbours {interp}; outliers {sum(o['count'] for o in m['outliers'])}"


# -- the campaign -----------------------------------------------------------------------------------

def prepare(work: Path, names: list[str], stamp_copies: bool, log=print) -> dict[str, dict[str, Base]]:
    """Per log: {"file": the shared file's Base, "copy": its uncompressed copy's Base (stamp classes)}."""
    out = {}
    for name in names:
        fname, ch = LOGS[name]
        src = write_synthetic_imu(work / "synthetic_imu.mcap") if fname is None else CAPSTAN / fname
        t = time.perf_counter()
        bases = {"file": Base(name, src, ch).load()}
        if stamp_copies:
            cp = work / f"{name}_uncompressed.mcap"
            if not cp.exists():
                uncompressed_copy(src, cp)
            bases["copy"] = Base(name, cp, ch).load()
        log(f"  {name}: {src.name} ({len(bases['file'].data)} bytes, {len(bases['file'].chunks)} chunks), "
            f"{bases['file'].ref.n_samples} samples at {bases['file'].ref.fs:.6g} Hz; ready in {time.perf_counter() - t:.1f} s")
        out[name] = bases
    return out


def run(n_per_class: int, seed: int, names: list[str], classes: list[str], work: Path, log=print) -> list[dict]:
    """`n_per_class` variants of each class (spread over the logs in turn); one row per variant."""
    rng = random.Random(seed)
    bases = prepare(work, names, bool(STAMP_CLASSES & set(classes)), log)
    rows = []
    variant = work / "variant.mcap"
    # the stamp classes damage logs whose channel is read on its header stamps (bagfile_0's joint states
    # carry stamps of 0 and are read on their log times: a moved stamp there changes nothing)
    stamped = [m for m in names if "copy" in bases[m]
               and bases[m]["copy"].ref.meta["timebase"][LOGS[m][1].split(".")[0]]["time_source"] == "header.stamp"]
    for kind in classes:
        pool = stamped if kind in STAMP_CLASSES and stamped else names
        for i in range(n_per_class):
            name = pool[i % len(pool)]
            base = bases[name]["copy" if kind in STAMP_CLASSES else "file"]
            data, desc = damage(kind, rng, base)
            variant.write_bytes(data)
            t = time.perf_counter()
            outcome, detail = check(base, variant)
            rows.append({"class": kind, "log": name, "damage": desc, "outcome": outcome, "detail": detail,
                         "seconds": round(time.perf_counter() - t, 3)})
            if outcome not in PASS:
                log(f"  FAIL {kind:13s} {name:13s} {outcome}: {desc} | {detail}")
    return rows


def summary(rows: list[dict], classes: list[str]) -> list[dict]:
    """Per class: variants, passes, pass rate and the count of each outcome."""
    out = []
    for c in classes:
        rs = [r for r in rows if r["class"] == c]
        cnt = {o: sum(r["outcome"] == o for r in rs) for o in OUTCOMES}
        npass = cnt["ok"] + cnt["refused"]
        out.append({"class": c, "variants": len(rs), "pass": npass, "rate": npass / len(rs) if rs else float("nan"), **cnt})
    return out


def write_outputs(rows: list[dict], table: list[dict], out: Path, title: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "damage_property.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = ["| class | variants | pass | pass rate | " + " | ".join(OUTCOMES) + " |",
             "|---|---:|---:|---:|" + "---:|" * len(OUTCOMES)]
    for t in table:
        lines.append(f"| {t['class']} | {t['variants']} | {t['pass']} | {100 * t['rate']:.1f} % | "
                     + " | ".join(str(t[o]) for o in OUTCOMES) + " |")
    tot = sum(t["variants"] for t in table)
    tp = sum(t["pass"] for t in table)
    lines.append(f"| **all** | {tot} | {tp} | {100 * tp / max(tot, 1):.1f} % | "
                 + " | ".join(str(sum(t[o] for t in table)) for o in OUTCOMES) + " |")
    (out / "damage_property.md").write_text(f"{title}\n\n" + "\n".join(lines) + "\n")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"ok": "#2e7d32", "refused": "#81c784", "bad_value": "#c62828", "silent_loss": "#ef6c00",
               "lost_unsaid": "#f9a825", "crash": "#6a1b9a"}
    fig, ax = plt.subplots(figsize=(9, 5.0))
    x = np.arange(len(table))
    bottom = np.zeros(len(table))
    for o in OUTCOMES:
        v = np.array([t[o] / max(t["variants"], 1) for t in table]) * 100
        ax.bar(x, v, bottom=bottom, color=colours[o], label=o.replace("_", " "), edgecolor="white", linewidth=0.5)
        bottom += v
    for xi, t in zip(x, table):
        ax.text(xi, 101.5, f"{100 * t['rate']:.0f} %\n(n={t['variants']})", ha="center", va="bottom", fontsize=8)
    ax.set_xticks(x, [t["class"].replace("_", " ") for t in table], rotation=25, ha="right")
    ax.set_ylabel("variants (%)")
    ax.set_ylim(0, 118)
    ax.set_title(title, fontsize=10)
    ax.legend(ncol=3, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.34), frameon=False)
    fig.tight_layout()
    fig.savefig(out / "damage_property.png", dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=64, help="variants in all (split evenly over the classes)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--logs", nargs="*", default=list(LOGS), choices=list(LOGS))
    ap.add_argument("--classes", nargs="*", default=CLASSES, choices=CLASSES)
    ap.add_argument("--out", type=Path, default=Path("damage_property_out"))
    args = ap.parse_args(argv)
    if not CAPSTAN.is_dir():
        print(f"shared logs not found at {CAPSTAN}", file=sys.stderr)
        return 2
    per = max(1, -(-args.n // len(args.classes)))
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        rows = run(per, args.seed, args.logs, args.classes, Path(tmp))
    table = summary(rows, args.classes)
    title = (f"read_mcap damage property: {len(rows)} variants of {len(args.logs)} logs, seed {args.seed} "
             f"({time.perf_counter() - t:.0f} s)")
    write_outputs(rows, table, args.out, title)
    print((args.out / "damage_property.md").read_text())
    return 0 if all(r["outcome"] in PASS for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
