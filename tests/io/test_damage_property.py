"""A bounded slice of ``examples/robustness/damage_property.py`` (issue 21, item 8): a few damaged variants
per class of two small shared capstan logs and a synthetic Imu log; every value read is the undamaged
one at its stamp or NaN (or, for a topic whose undamaged stamps already need interpolation, between
its two undamaged neighbours), and every loss is reported. The full campaign (>= 500 variants of
the five capstan logs) runs outside CI."""

from __future__ import annotations

import importlib.util
import random
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "examples" / "robustness" / "damage_property.py"
LOGS = ["synthetic_imu", "controlled", "uncontrolled"]
PER_CLASS = 3


@pytest.fixture(scope="module")
def dp():
    spec = importlib.util.spec_from_file_location("damage_property", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # its dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def bases(dp, shared_data, tmp_path_factory):
    return dp.prepare(tmp_path_factory.mktemp("dp"), LOGS, True, log=lambda *_: None)


def _variants(dp, bases, kind, tmp_path, logs=LOGS, n=PER_CLASS, seed=0):
    rng = random.Random(f"{kind}-{seed}")
    out = []
    for i in range(n):
        base = bases[logs[i % len(logs)]]["copy" if kind in dp.STAMP_CLASSES else "file"]
        data, desc = dp.damage(kind, rng, base)
        p = tmp_path / f"{kind}_{i}.mcap"
        p.write_bytes(data)
        out.append((base, p, desc))
    return out


@pytest.mark.parametrize("kind", ["truncate", "bitflip", "zero4k", "nudge", "nanosec", "shift_summary", "lying_size"])
def test_damage_property(dp, bases, kind, tmp_path):
    for base, p, desc in _variants(dp, bases, kind, tmp_path):
        outcome, detail = dp.check(base, p)
        assert outcome in dp.PASS, f"{kind} on {base.name} ({desc}): {outcome}: {detail}"


def test_deleted_middle_chunk_is_a_counted_gap(dp, bases, tmp_path):
    """A chunk deleted from a log of many chunks: the rest read, the lost span NaN and reported."""
    base = bases["synthetic_imu"]["file"]
    for i, (_op, a, e) in enumerate(base.chunks[40:43]):
        d = base.data
        p = tmp_path / f"del{i}.mcap"
        recs = base.recs
        j = recs.index((_op, a, e)) + 1
        while j < len(recs) and recs[j][0] == dp.OP_MESSAGE_INDEX:
            e = recs[j][2]
            j += 1
        p.write_bytes(d[:a] + d[e:])
        outcome, detail = dp.check(base, p)
        assert outcome == "ok" and not detail.startswith("lost 0"), detail


@pytest.mark.parametrize("log", ["controlled", "synthetic_imu"])
def test_deleted_first_chunk_is_said(dp, bases, tmp_path, log):
    (base, p, desc), = _variants(dp, bases, "delete_first_chunk", tmp_path, logs=[log], n=1)
    outcome, detail = dp.check(base, p)
    assert outcome in dp.PASS, f"{desc}: {outcome}: {detail}"


def test_the_check_fails_on_a_changed_value(dp, bases, tmp_path):
    """The property can fail: a variant whose one sample was changed (CRC cleared) is a bad value."""
    import struct

    base = bases["synthetic_imu"]["copy"]
    a, e, _lt = base.channel_messages()[5000]
    b = bytearray(base.data)
    off = e - 8 * 9 - 3 * 8  # linear_acceleration.x: before its 3 values and the 9-value covariance at the end
    assert struct.unpack_from("<d", b, off)[0] == base.ref.data[0, 5000]
    struct.pack_into("<d", b, off, 7.5)
    dp._zero_chunk_crc(b, base.chunks, off)
    p = tmp_path / "changed.mcap"
    p.write_bytes(bytes(b))
    outcome, detail = dp.check(base, p)
    assert outcome == "bad_value" and "7.5" in detail, (outcome, detail)
