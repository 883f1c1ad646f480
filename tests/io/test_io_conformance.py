"""The MCAP format's conformance suite (foxglove/mcap tests/conformance/data, MIT):
every file's messages as read by our scanner match the expected records in its .json."""

from __future__ import annotations

import json
from collections import Counter

from vibroscope.io import iter_raw_messages, mcap_info


def _expected(js: dict):
    channels, msgs = {}, []
    for rec in js["records"]:
        f = dict((k, v) for k, v in rec["fields"])
        if rec["type"] == "Channel":
            channels[int(f["id"])] = f["topic"]
        elif rec["type"] == "Message":
            msgs.append((int(f["channel_id"]), int(f["log_time"]), bytes(int(b) for b in f["data"])))
    return channels, msgs


def test_conformance_suite(shared_data):
    root = shared_data / "mcap" / "conformance"
    files = sorted(root.rglob("*.mcap"))
    assert len(files) > 400
    with_messages = 0
    for f in files:
        js = json.loads(f.with_suffix(".json").read_text())
        channels, msgs = _expected(js)
        got = list(iter_raw_messages(f))
        exp = Counter((channels.get(c, ""), c, t, d) for c, t, d in msgs)
        assert Counter((tp, c, t, d) for tp, c, t, d in got) == exp, f.name
        # file order within the data section is kept
        assert [t for _, _, t, _ in got] == [t for _, t, _ in msgs], f.name
        if msgs:
            with_messages += 1
            info = mcap_info(f)
            assert info.message_count == len(msgs), f.name
            assert info.skipped == (), f.name
            by_topic = Counter(channels[c] for c, _, _ in msgs)
            assert {t.topic: t.message_count for t in info.topics if t.message_count} == dict(by_topic), f.name
    assert with_messages > 100
