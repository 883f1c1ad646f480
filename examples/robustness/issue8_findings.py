"""Re-run every finding of issue #8 ("what a test of today's main found") and say whether it is fixed.

Each check builds its own input (synthetic logs written with vibroscope's and mcap's writers, the
real capstan recordings when ``../shared/data`` is present), runs what the issue ran, and prints
``PASS``/``FAIL`` with the number that decides it. Run from the repository root::

    python examples/robustness/issue8_findings.py [--shared ../shared/data] [--big 1000000]

Exit status 1 when any check fails.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

RESULTS: list[tuple[str, bool, str]] = []


def check(name: str, ok: bool, detail: str) -> None:
    RESULTS.append((name, bool(ok), detail))
    print(f"{'PASS' if ok else 'FAIL'}  {name}: {detail}", flush=True)


def cli(*argv: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vibroscope.cli", *argv], cwd=cwd, capture_output=True, text=True)


def one_line(p: subprocess.CompletedProcess) -> bool:
    err = [ln for ln in p.stderr.splitlines() if ln.strip()]
    return "Traceback" not in p.stderr and 1 <= len(err) <= 3


def imu_signals(n: int, fs: float = 1000.0, seed: int = 0):
    from vibroscope.signals import Signals

    x = np.random.default_rng(seed).standard_normal((1, n))
    return Signals(data=x, fs=fs, channels=["/imu.linear_acceleration.x"], units=["m/s^2"], t0=100.0)


def chunk_offsets(path: Path) -> list[tuple[int, int, int]]:
    """(offset, end, messages) of every chunk, from an intact file."""
    from vibroscope.io._scan import scan

    data = path.read_bytes()
    out = []
    for b in scan(path).blocks:
        if b.file_offset >= 0:
            length = struct.unpack_from("<Q", data, b.file_offset + 1)[0]
            out.append((b.file_offset, b.file_offset + 9 + length, b.n))
    return out


# ---------------------------------------------------------------------------------------------
def crc_damaged_chunks(tmp: Path) -> None:
    from vibroscope.io import read_mcap, write_ros2_mcap

    sig = imu_signals(40_000)
    p = tmp / "crc.mcap"
    write_ros2_mcap(p, sig, chunk_size=64_000, compression="none")
    chunks = chunk_offsets(p)
    data = bytearray(p.read_bytes())
    lost = 0
    for off, end, n in (chunks[3], chunks[8]):
        data[(off + end) // 2] ^= 0x10  # inside the message data: the CRC catches it
        lost += n
    q = tmp / "crc_damaged.mcap"
    q.write_bytes(bytes(data))
    r = read_mcap(q, ["/imu.linear_acceleration.x"])
    y = r.data[0]
    finite = int(np.isfinite(y).sum())
    ok_vals = np.isfinite(y)
    # every finite sample is the original one at its stamp (same grid: t0 identical)
    i0 = int(round((r.t0 - sig.t0) * sig.fs))
    same = np.array_equal(y[ok_vals], sig.data[0, i0 : i0 + y.size][ok_vals])
    reported = sum("offset" in s for s in r.meta["skipped"])
    check("two CRC-damaged chunks: skipped, reported, never filled", finite == sig.n_samples - lost and same
          and reported >= 2, f"{finite} finite samples of {sig.n_samples} ({lost} lost), {reported} reports, "
          f"values unchanged: {same}")


def capstan_gaps(shared: Path | None) -> None:
    if shared is None:
        return
    from vibroscope.io import mcap_info, read_mcap

    worst = ""
    ok = True
    for f in sorted((shared / "mcap" / "capstan").glob("*.mcap")):
        info = mcap_info(f)
        for t in info.topics:
            if not t.decodable or t.message_count < 100:
                continue
            try:
                from vibroscope.io import discover_fields

                fields = discover_fields(f).get(t.topic, [])
                fields = [c for c in fields if "stamp" not in c][:1]
                if not fields:
                    continue
                r = read_mcap(f, fields)
            except Exception as exc:  # noqa: BLE001
                if type(exc).__name__ not in ("ChannelError", "LogFormatError"):
                    ok = False
                    worst += f" {f.name}:{t.topic}: {type(exc).__name__}"
                continue
            finite = int(np.isfinite(r.data[0]).sum())
            if finite > t.message_count * 1.01 + 2:
                ok = False
                worst += f" {f.name}:{t.topic}: {finite} finite > {t.message_count} messages"
    check("capstan recordings: never more finite samples than messages", ok, worst.strip() or "every topic")


def nan_in_analysis(tmp: Path) -> None:
    from vibroscope.commands.demo import make_demo_log
    from vibroscope.io import read_mcap
    from vibroscope.pipeline import analyse_signals

    log = tmp / "demo.mcap"
    model, _ = make_demo_log(log, duration=60.0)
    truth = model.modes().natural_frequencies
    sig = read_mcap(log)
    force = model.input_channels()[0]
    sig_all = read_mcap(log, [force, *sig.channels])
    for what, row in (("ten NaN in an accelerometer channel", 1), ("one NaN in the force channel", 0)):
        d = sig_all.data.copy()
        d[row, 20_000 : 20_010 if row else 20_001] = np.nan
        s = sig_all.with_data(d) if hasattr(sig_all, "with_data") else type(sig_all)(
            d, sig_all.fs, sig_all.channels, sig_all.units, sig_all.t0, sig_all.meta)
        try:
            an = analyse_signals(s, input=force, fmin=5.0, fmax=150.0)
            f = an.modal.natural_frequencies
            errs = [float(np.min(abs(f - t)) / t) if f.size else 1.0 for t in truth]
            said = any("nan" in w.lower() or "missing" in w.lower() for w in an.warnings)
            check(what, max(errs) < 0.005 and said, f"{f.size} modes, max error {100 * max(errs):.3f} %, "
                  f"reported: {said}")
        except Exception as exc:  # noqa: BLE001
            check(what, False, f"{type(exc).__name__}: {exc}")


def convert_checks(tmp: Path) -> None:
    import scipy.io

    from vibroscope.io import read_mcap

    csv = tmp / "data.csv"
    np.savetxt(csv, np.random.default_rng(1).standard_normal((500, 2)), delimiter=",")
    p = cli("convert", str(csv), str(tmp / "c.mcap"), "--columns", "0-1", cwd=tmp)
    check("convert CSV without --fs: one-line error", p.returncode in (1, 2) and one_line(p) and "--fs" in p.stderr,
          f"exit {p.returncode}: {p.stderr.strip()[:120]}")
    x = np.random.default_rng(2).standard_normal(1000)
    labels = []
    for k, order in enumerate((("force", "acc"), ("acc", "force"))):
        mat = tmp / f"m{k}.mat"
        scipy.io.savemat(mat, {"fs": 1000.0, **{name: x * (j + 1) for j, name in enumerate(order)}})
        out = tmp / f"m{k}.mcap"
        p = cli("convert", str(mat), str(out), "--channels", "force,acc", "--units", "force=N,acc=m/s^2", cwd=tmp)
        if p.returncode:
            check(".mat convert by name", False, p.stderr.strip()[:160])
            return
        from vibroscope.io import discover_fields

        fields = [c for v in discover_fields(out).values() for c in v if "stamp" not in c]
        r = read_mcap(out, fields)
        named = {c: u for c, u in zip(r.channels, r.units) if c.endswith((".force", ".acc", "linear_acceleration.x"))}
        labels.append({("force" if "force" in c else "acc"): u for c, u in named.items()})
        if not np.allclose(r.data[r.channels.index(next(c for c in r.channels if "force" in c))],
                           x * (order.index("force") + 1)):
            labels[-1]["values"] = "force channel holds the wrong variable"
    check(".mat: --channels/--units by name, same labels whatever the variable order",
          labels[0] == labels[1] == {"force": "N", "acc": "m/s^2"}, f"{labels}")


def auto_outputs_exclude_input(tmp: Path) -> None:
    from vibroscope.io import write_ros2_mcap
    from vibroscope.signals import Signals

    rng = np.random.default_rng(3)
    s = Signals(data=rng.standard_normal((3, 4000)), fs=1000.0, channels=["/ft.wrench.force.x", "/acc.a", "/acc.b"],
                units=["N", "m/s^2", "m/s^2"], t0=10.0)
    log = tmp / "noimu.mcap"
    write_ros2_mcap(log, s)
    p = cli("analyse", str(log), "--input", "/ft.wrench.force.x", "--no-rrd", cwd=tmp)
    check("no Imu + --input: the input is not an output", "repeat" not in p.stderr and p.returncode in (0, 1)
          and "Traceback" not in p.stderr, f"exit {p.returncode} {p.stderr.strip()[:120]}")
    raw = [ln for ln in p.stderr.splitlines() if "Warning:" in ln or ln.startswith("  ")]
    check("warnings print as one line each (no raw Python warnings)", not raw, raw[0][:140] if raw else "none raw")


def outputs_checks(tmp: Path, shared: Path | None) -> None:
    from vibroscope.commands.demo import make_demo_log

    ro = tmp / "ro"
    log = ro / "small.mcap"
    make_demo_log(log, duration=20.0)
    os.chmod(ro, 0o555)
    work = tmp / "work"
    work.mkdir()
    try:
        p1 = cli("analyse", str(log), cwd=work)
        made = sorted(q.name for q in work.iterdir())
        check("analyse on a read-only data folder writes to the current directory", p1.returncode == 0 and
              bool(made), f"exit {p1.returncode}, wrote {made} {p1.stderr.strip()[-160:]}")
        p2 = cli("analyse", str(log), cwd=work)
        said = "replac" in (p2.stdout + p2.stderr).lower() or "overwr" in (p2.stdout + p2.stderr).lower()
        check("a second analyse says it replaces the first run's outputs", p2.returncode == 0 and said,
              f"exit {p2.returncode}, said so: {said}")
    finally:
        os.chmod(ro, 0o755)
    # outputs never overwrite an input
    for argv, victim in ((["analyse", "LOG", "--json", "LOG"], "LOG"), (["analyse", "LOG", "--rrd", "LOG"], "LOG"),
                         (["convert", "LOG", "LOG"], "LOG")):
        w = tmp / f"victim_{len(RESULTS)}"
        w.mkdir()
        shutil.copy(log, w / "x.mcap")
        before = (w / "x.mcap").read_bytes()
        a = [s.replace("LOG", "x.mcap") for s in argv]
        p = cli(*a, cwd=w)
        check(f"`{' '.join(a)}` leaves its input intact", (w / "x.mcap").read_bytes() == before
              and p.returncode in (1, 2) and one_line(p), f"exit {p.returncode}: {p.stderr.strip()[:120]}")
    w = tmp / "victim_rrd"
    w.mkdir()
    (w / "x.rrd").write_bytes(b"not a log, a recording")
    p = cli("analyse", "x.rrd", cwd=w)
    check("`analyse X.rrd` refuses and leaves it intact", (w / "x.rrd").read_bytes() == b"not a log, a recording"
          and p.returncode == 1 and one_line(p), f"exit {p.returncode}: {p.stderr.strip()[:120]}")
    model = Path(__file__).resolve().parents[2] / "examples" / "models" / "three_dof.toml"
    if model.exists():
        shutil.copy(model, w / "m.toml")
        before = (w / "m.toml").read_bytes()
        p = cli("simulate", "m.toml", "--excitation", "random:fmin=1,fmax=100,rms=1", "--duration", "2", "--out", "m.toml", cwd=w)
        check("`simulate M.toml --out M.toml` leaves the model intact", (w / "m.toml").read_bytes() == before
              and p.returncode == 1, f"exit {p.returncode}: {p.stderr.strip()[:120]}")


def complex_input() -> None:
    from vibroscope.spectral import csd_matrix, welch
    from vibroscope.signals import Signals

    z = (np.random.default_rng(4).standard_normal((2, 4096)) * (1 + 1j))
    for fn in (welch, csd_matrix):
        try:
            if fn is csd_matrix:
                fn(Signals(data=z, fs=100.0, channels=["a", "b"]), nperseg=256)
            else:
                fn(z, fs=100.0, nperseg=256)
            check(f"complex input to {fn.__name__}", False, "accepted silently")
        except (TypeError, ValueError) as exc:
            check(f"complex input to {fn.__name__}", "complex" in str(exc).lower(), str(exc)[:100])
        except Exception as exc:  # noqa: BLE001
            check(f"complex input to {fn.__name__}", "complex" in str(exc).lower(), f"{type(exc).__name__}: {exc}"[:100])


def flipped_stamp(tmp: Path) -> None:
    """38 s at 100 Hz; one message's header.stamp.sec has bit 20 flipped (12 days later), its log
    time intact: what a bit flip in a chunk written without CRC gives."""
    from mcap_ros2.writer import Writer as Ros2Writer

    from vibroscope.io import read_mcap
    from vibroscope.io._ros2 import MSGDEFS

    n = 3795
    x = np.random.default_rng(5).standard_normal(n)
    p = tmp / "stamp_flipped.mcap"
    with open(p, "wb") as fh:
        w = Ros2Writer(fh)
        schema = w.register_msgdef("sensor_msgs/msg/Imu", MSGDEFS["sensor_msgs/msg/Imu"])
        for k in range(n):
            t = 100 * 10**9 + k * 10**7
            sec, nsec = divmod(t, 10**9)
            if k == 2000:
                sec ^= 1 << 20
            msg = {"header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": "imu"},
                   "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}, "orientation_covariance": [-1.0] + [0.0] * 8,
                   "angular_velocity": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular_velocity_covariance": [0.0] * 9,
                   "linear_acceleration": {"x": float(x[k]), "y": 0.0, "z": 0.0},
                   "linear_acceleration_covariance": [0.0] * 9}
            w.write_message("/imu", schema, msg, log_time=t)
        w.finish()
    try:
        r = read_mcap(p, ["/imu.linear_acceleration.x"])
        said = any("outlier" in w.lower() for w in r.meta["warnings"])
        y = r.data[0]
        same = np.array_equal(y[np.isfinite(y)], np.delete(x, 2000)[: int(np.isfinite(y).sum())])
        check("one flipped stamp bit does not stretch the grid", r.n_samples <= n and said and same,
              f"{r.n_samples} samples (of {n}), reported: {said}, other samples unchanged: {same}")
    except Exception as exc:  # noqa: BLE001
        check("one flipped stamp bit does not stretch the grid", False, f"{type(exc).__name__}: {exc}"[:160])


def repeat_channels_false(tmp: Path) -> None:
    from mcap.writer import Writer

    from vibroscope.io import read_mcap

    p = tmp / "norepeat.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh, repeat_channels=False, chunk_size=2000)
        w.start()
        sid = w.register_schema("S", "jsonschema", b"{}")
        cid = w.register_channel("/j", "json", sid)
        for k in range(500):
            w.add_message(cid, log_time=10**9 + k * 10**7, publish_time=0,
                          data=json.dumps({"v": float(np.sin(k / 7))}).encode())
        w.finish()
    try:
        r = read_mcap(p, ["/j.v"])
        check("repeat_channels=False: explicit channel read", r.n_samples == 500, f"{r.n_samples} samples")
    except Exception as exc:  # noqa: BLE001
        check("repeat_channels=False: explicit channel read", False, f"{type(exc).__name__}: {exc}"[:160])


def recovery(tmp: Path, big: int) -> None:
    from vibroscope.io import iter_raw_messages, mcap_info, write_ros2_mcap

    sig = imu_signals(big)
    p = tmp / "big.mcap"
    write_ros2_mcap(p, sig)
    chunks = chunk_offsets(p)
    data = bytearray(p.read_bytes())
    off, end, n = chunks[len(chunks) // 10]
    data[off : off + 9] = bytes(9)
    q = tmp / "zero9.mcap"
    q.write_bytes(bytes(data))
    got = sum(1 for _ in iter_raw_messages(q))
    check("9 zeroed bytes at one chunk's start lose that chunk at most", got >= big - n,
          f"{got} of {big} messages (the chunk held {n}; read through the summary's chunk index when intact)")
    data = bytearray(p.read_bytes())
    hlen = struct.unpack_from("<Q", data, 9)[0]
    data[8 : 8 + 9 + hlen] = bytes(9 + hlen)
    q = tmp / "zeroheader.mcap"
    q.write_bytes(bytes(data))
    try:
        got = sum(1 for _ in iter_raw_messages(q))
        check("zeroed Header record: every message read", got == big, f"{got} of {big}")
    except Exception as exc:  # noqa: BLE001
        check("zeroed Header record: every message read", False, f"{type(exc).__name__}: {exc}"[:160])
    data = bytearray(p.read_bytes())
    off, end, n = chunks[2]
    data[off:end] = bytes(end - off)
    q = tmp / "zerochunk.mcap"
    q.write_bytes(bytes(data))
    info = mcap_info(q)
    check("a zeroed chunk is reported", len(info.skipped) >= 1 and info.message_count == big - n,
          f"{info.message_count} of {big} messages, {len(info.skipped)} reports: "
          f"{info.skipped[0][1][:80] if info.skipped else ''}")
    # a bit flip in the summary: `info` prints no traceback
    data = bytearray(p.read_bytes())
    fpos = len(data) - 8 - 29
    summary_start = struct.unpack_from("<Q", data, fpos + 9)[0]
    data[summary_start + 20] ^= 0x04
    q = tmp / "summaryflip.mcap"
    q.write_bytes(bytes(data))
    pr = cli("info", str(q), cwd=tmp)
    check("a bit flip in the summary: `info` reads the log", pr.returncode == 0 and "Traceback" not in pr.stderr,
          f"exit {pr.returncode} {pr.stderr.strip()[:100]}")


def corrupted_message(tmp: Path) -> None:
    from mcap.writer import Writer

    from vibroscope.io import read_mcap

    p = tmp / "badmsg.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh, chunk_size=1 << 20)
        w.start()
        sid = w.register_schema("S", "jsonschema", b"{}")
        cid = w.register_channel("/j", "json", sid)
        for k in range(500):
            payload = json.dumps({"v": float(k)}).encode() if k != 250 else b'{"v": 1.0, broken'
            w.add_message(cid, log_time=10**9 + k * 10**7, publish_time=0, data=payload)
        w.finish()
    try:
        r = read_mcap(p, ["/j.v"], fs=100.0)
        y = r.data[0]
        ok = int(np.isfinite(y).sum()) == 499 and bool(np.isnan(y[250]))
        check("one corrupted message: the channel is read, that sample NaN", ok,
              f"{int(np.isfinite(y).sum())} finite of {y.size}")
    except Exception as exc:  # noqa: BLE001
        check("one corrupted message: the channel is read, that sample NaN", False, f"{type(exc).__name__}: {exc}"[:160])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=Path(__file__).resolve().parents[3] / "shared" / "data")
    ap.add_argument("--big", type=int, default=1_000_000, help="messages of the recovery log (the issue: 1e6)")
    args = ap.parse_args()
    shared = args.shared if args.shared.is_dir() else None
    warnings.simplefilter("ignore")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for fn in (crc_damaged_chunks, nan_in_analysis, convert_checks, auto_outputs_exclude_input, complex_input,
                   flipped_stamp, repeat_channels_false, corrupted_message):
            sub = tmp / fn.__name__
            sub.mkdir()
            try:
                fn(sub) if fn is not complex_input else fn()
            except Exception as exc:  # noqa: BLE001
                check(fn.__name__, False, f"crashed: {type(exc).__name__}: {exc}"[:200])
        for fn, a in ((outputs_checks, (shared,)), (recovery, (args.big,)), (capstan_gaps, None)):
            sub = tmp / fn.__name__
            sub.mkdir()
            try:
                fn(sub, *a) if a is not None else fn(shared)
            except Exception as exc:  # noqa: BLE001
                check(fn.__name__, False, f"crashed: {type(exc).__name__}: {exc}"[:200])
    bad = [r for r in RESULTS if not r[1]]
    print(f"\n{len(RESULTS) - len(bad)} of {len(RESULTS)} checks pass")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
