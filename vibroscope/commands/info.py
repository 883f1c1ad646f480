"""``vibroscope info LOG.mcap [--json]``: topics, types, counts, rates, time span and gaps
(log-time increments over 1.5 median periods, and the time missing in them), outlier log
times and messages lost in damaged or missing chunks of a log. ``--fields`` (or ``--topic T``)
lists the numeric message paths instead, with their unit and a sample value: the paths
``--input``/``--outputs`` take."""

from __future__ import annotations

import json
import math


def add_parser(sub) -> None:
    """Register the ``info`` sub-command."""
    p = sub.add_parser("info", help="list the topics of an MCAP log (type, count, rate, span, decodable)")
    p.add_argument("log", metavar="LOG.mcap", help="the MCAP file")
    p.add_argument("--json", action="store_true",
                   help="print JSON instead of a table (strict JSON: a value that is not a number is null)")
    p.add_argument("--fields", action="store_true",
                   help="list every numeric message path (what --input/--outputs take) with unit and a sample value")
    p.add_argument("--topic", action="append", metavar="TOPIC",
                   help="list the numeric message paths of this topic (repeatable; implies --fields)")
    p.set_defaults(func=run)


def _fmt_rate(r: float) -> str:
    return "-" if not math.isfinite(r) else f"{r:.4g}"


def run_fields(args) -> int:
    """Print the numeric message paths of the log (of ``--topic`` only when given), each with its
    unit and its value in the topic's first message (:func:`vibroscope.io.select.numeric_fields`);
    returns the exit status."""
    from vibroscope.io.select import numeric_fields

    fields = numeric_fields(args.log, args.topic)
    if args.json:
        print(json.dumps({"path": str(args.log), "fields": [
            {"path": f.path, "unit": f.unit, "sample": f.sample if math.isfinite(f.sample) else None,
             "type": f.schema} for f in fields]}, indent=2))
        return 0
    rows = [("path", "unit", "sample", "type")]
    rows += [(f.path, f.unit or "-", f"{f.sample:.6g}", f.schema or "-") for f in fields]
    w = [max(len(r[i]) for r in rows) for i in range(3)]
    for r in rows:
        print(f"{r[0].ljust(w[0])}  {r[1].ljust(w[1])}  {r[2].rjust(w[2])}  {r[3]}")
    print(f"{len(fields)} numeric paths in {len({f.topic for f in fields})} topics"
          " (the sample is the first message's value)")
    return 0


def run(args) -> int:
    """Print the log's summary (or its numeric paths, :func:`run_fields`); returns the exit status."""
    from vibroscope.io import mcap_info

    if getattr(args, "fields", False) or getattr(args, "topic", None):
        return run_fields(args)
    info = mcap_info(args.log)
    if args.json:
        # strict JSON: a rate or span that is not a number (a topic of < 2 messages) is null, never NaN
        text = json.dumps(info.as_dict(), default=str)
        print(json.dumps(json.loads(text, parse_constant=lambda c: None), indent=2, allow_nan=False))
        return 0
    print(f"{info.path}: {info.message_count} messages, {len(info.topics)} topics, {info.duration_s:.3f} s"
          f"{' (profile ' + info.profile + ')' if info.profile else ''}")
    # lost: messages of the topic in damaged or missing chunks ("?" where a damaged place names it without a count)
    rows = [("topic", "type", "enc", "messages", "rate Hz", "span s", "gaps", "missing s", "outliers", "lost",
             "decodable")]
    for t in info.topics:
        span = (t.end_ns - t.start_ns) * 1e-9 if t.message_count else 0.0
        lost = "?" if t.lost_messages is None else str(t.lost_messages)
        rows.append((t.topic, t.schema_name or "-", t.message_encoding, str(t.message_count), _fmt_rate(t.rate_hz),
                     f"{span:.3f}", str(t.gaps), f"{t.gap_time_s:.3f}", str(t.outliers), lost,
                     "yes" if t.decodable else f"no: {t.reason}"))
    w = [max(len(r[i]) for r in rows) for i in range(10)]
    for r in rows:
        cells = (c.ljust(w[i]) if i in (0, 1, 2) else c.rjust(w[i]) for i, c in enumerate(r[:10]))
        print("  ".join(cells) + "  " + r[10])
    for off, reason in info.skipped:
        print(f"skipped at byte offset {off}: {reason}")
    for wmsg in info.warnings:
        print(f"warning: {wmsg}")
    return 0
