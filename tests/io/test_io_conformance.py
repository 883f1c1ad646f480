"""The MCAP format's conformance suite (foxglove/mcap tests/conformance/data, MIT):
every file's messages as read by our scanner match the expected records in its .json,
through every reading path of :func:`vibroscope.io._scan.scan`."""

from __future__ import annotations

import json
from collections import Counter

import pytest

from vibroscope.io import iter_raw_messages, mcap_info
from vibroscope.io._scan import scan


def _expected(js: dict):
    channels, msgs = {}, []
    for rec in js["records"]:
        f = dict((k, v) for k, v in rec["fields"])
        if rec["type"] == "Channel":
            channels[int(f["id"])] = f["topic"]
        elif rec["type"] == "Message":
            msgs.append((int(f["channel_id"]), int(f["log_time"]), bytes(int(b) for b in f["data"])))
    return channels, msgs


def _files(shared_data):
    root = shared_data / "mcap" / "conformance"
    files = sorted(root.rglob("*.mcap"))
    assert len(files) > 400
    return files


def test_conformance_suite(shared_data):
    files = _files(shared_data)
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


PATHS = {
    "stream": dict(mode="stream"),
    "stream-slow": dict(mode="stream", fast=False),
    "indexed": dict(mode="indexed"),
    "indexed-slow": dict(mode="indexed", fast=False),
    "auto": dict(mode="auto"),
    "auto-slow": dict(mode="auto", fast=False),
}


@pytest.mark.parametrize("path", list(PATHS))
def test_conformance_every_reading_path(shared_data, path):
    """Each file read through one path gives exactly its .json's messages, nothing skipped."""
    kw = PATHS[path]
    n_indexed = 0
    for f in _files(shared_data):
        channels, msgs = _expected(json.loads(f.with_suffix(".json").read_text()))
        res = scan(f, **kw)
        assert Counter(res.messages()) == Counter(msgs), f"{f.name} via {path}"
        assert res.skipped == [] and res.damage == [], f"{f.name} via {path}: {res.skipped}"
        assert {c: ch.topic for c, ch in res.channels.items() if c in channels} == {
            c: channels[c] for c in channels if c in res.channels}, f.name
        assert {c for c, _, _ in msgs} <= res.channels.keys(), f.name
        if kw["mode"] == "stream":
            assert not res.indexed
        n_indexed += res.indexed
        if kw["mode"] == "indexed" and not res.indexed:
            assert any("linear pass" in w for w in res.warnings), f.name
    if kw["mode"] != "stream":
        assert n_indexed > 100  # the summary path is really taken


def test_conformance_filtered_by_each_topic(shared_data):
    """``topics={t}`` (the chunk-index filter): the messages of topic t are exactly the expected
    ones, on every file, including those written with channels only inside chunks."""
    pairs = 0
    for f in _files(shared_data):
        channels, msgs = _expected(json.loads(f.with_suffix(".json").read_text()))
        for topic in sorted(set(channels.values())):
            ids = {c for c, t in channels.items() if t == topic}
            res = scan(f, topics={topic})
            got = [m for m in res.messages() if m[0] in ids]
            assert Counter(got) == Counter(m for m in msgs if m[0] in ids), f"{f.name} topic {topic}"
            assert res.skipped == [], f.name
            pairs += 1
    assert pairs > 300
