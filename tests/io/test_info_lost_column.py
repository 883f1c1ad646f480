"""``vibroscope info`` says, per topic, the messages lost in damaged or missing chunks (column ``lost``)."""

from __future__ import annotations

import numpy as np

from vibroscope.cli import main
from vibroscope.io import mcap_info
from vibroscope.io.mcap_write import write_ros2_mcap
from vibroscope.signals import Signals
from tests.io.test_io_chunk_loss import _chunks, _delete


def _table(out: str) -> dict[str, dict[str, str]]:
    """Rows of the info table by topic: column name -> cell (the columns before ``decodable``)."""
    lines = out.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("topic "))
    head = lines[k].split()[:-1]  # ... "missing s" is two words: rebuild the names
    names = []
    for h in head:
        if names and h in ("Hz", "s"):
            names[-1] += f" {h}"
        else:
            names.append(h)
    rows = {}
    for ln in lines[k + 1:]:
        if not ln.startswith("/"):
            break
        cells = ln.split()
        rows[cells[0]] = dict(zip(names, cells))
    return rows


def test_info_table_counts_the_messages_of_a_deleted_chunk(tmp_path, capsys):
    n, fs = 4000, 1000.0
    x = np.random.default_rng(3).standard_normal((2, n))
    p = tmp_path / "ok.mcap"
    write_ros2_mcap(p, Signals(data=x, fs=fs, channels=["/imu.linear_acceleration.x", "/imu.linear_acceleration.y"]),
                    chunk_size=32_000)
    data = p.read_bytes()
    assert main(["info", str(p)]) == 0
    row = _table(capsys.readouterr().out)["/imu"]
    assert row["lost"] == "0" and row["messages"] == str(n)
    q = tmp_path / "del.mcap"
    q.write_bytes(_delete(data, _chunks(p, data)[2], True))
    k = n - mcap_info(q).topic("/imu").message_count
    assert k > 0
    assert main(["info", str(q)]) == 0
    row = _table(capsys.readouterr().out)["/imu"]
    assert row["lost"] == str(k) and row["messages"] == str(n - k)
