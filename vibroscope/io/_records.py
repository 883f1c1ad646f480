"""MCAP record framing shared by the scan's modules: the magic, the record and message headers,
opcode names and validity, and one record body parsed by ``mcap``'s own parser."""

from __future__ import annotations

import struct
from io import BytesIO
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode

MAGIC = b"\x89MCAP0\r\n"
MSG_HDR = struct.Struct("<HIQQ")  # channel_id, sequence, log_time, publish_time
REC_HDR = struct.Struct("<BQ")
FOOTER_LEN = 1 + 8 + 20


def opname(op: int) -> str:
    """The opcode's name (``"CHUNK"``), or ``"opcode 0x.."`` for one MCAP does not define."""
    try:
        return Opcode(op).name
    except ValueError:
        return f"opcode 0x{op:02x}"


def valid_opcode(op: int) -> bool:
    """Defined opcodes (0x01–0x0F) and the private range (0x80–0xFF); 0x00 and 0x10–0x7F are damage."""
    return 0x01 <= op <= 0x0F or op >= 0x80


def parse_record(cls: Any, body: bytes) -> Any:
    """The record of type `cls` (an ``mcap.records`` class) whose body is `body`, by mcap's parser."""
    return cls.read(ReadDataStream(BytesIO(body)))

