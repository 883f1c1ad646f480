"""``vibroscope info LOG.mcap [--json]``: topics, types, counts, rates, time span and gaps
(log-time increments over 1.5 median periods, and the time missing in them) and outlier log
times of a log."""

from __future__ import annotations

import json
import math


def add_parser(sub) -> None:
    """Register the ``info`` sub-command."""
    p = sub.add_parser("info", help="list the topics of an MCAP log (type, count, rate, span, decodable)")
    p.add_argument("log", metavar="LOG.mcap", help="the MCAP file")
    p.add_argument("--json", action="store_true",
                   help="print JSON instead of a table (strict JSON: a value that is not a number is null)")
    p.set_defaults(func=run)


def _fmt_rate(r: float) -> str:
    return "-" if not math.isfinite(r) else f"{r:.4g}"


def run(args) -> int:
    """Print the log's summary; returns the exit status."""
    from vibroscope.io import mcap_info

    info = mcap_info(args.log)
    if args.json:
        # strict JSON: a rate or span that is not a number (a topic of < 2 messages) is null, never NaN
        text = json.dumps(info.as_dict(), default=str)
        print(json.dumps(json.loads(text, parse_constant=lambda c: None), indent=2, allow_nan=False))
        return 0
    print(f"{info.path}: {info.message_count} messages, {len(info.topics)} topics, {info.duration_s:.3f} s"
          f"{' (profile ' + info.profile + ')' if info.profile else ''}")
    rows = [("topic", "type", "enc", "messages", "rate Hz", "span s", "gaps", "missing s", "outliers", "decodable")]
    for t in info.topics:
        span = (t.end_ns - t.start_ns) * 1e-9 if t.message_count else 0.0
        rows.append((t.topic, t.schema_name or "-", t.message_encoding, str(t.message_count), _fmt_rate(t.rate_hz),
                     f"{span:.3f}", str(t.gaps), f"{t.gap_time_s:.3f}", str(t.outliers), "yes" if t.decodable else f"no: {t.reason}"))
    w = [max(len(r[i]) for r in rows) for i in range(9)]
    for r in rows:
        print("  ".join(c.ljust(w[i]) if i in (0, 1, 2) else c.rjust(w[i]) for i, c in enumerate(r[:9])) + "  " + r[9])
    for off, reason in info.skipped:
        print(f"skipped at byte offset {off}: {reason}")
    for wmsg in info.warnings:
        print(f"warning: {wmsg}")
    return 0
