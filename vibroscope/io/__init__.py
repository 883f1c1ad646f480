"""MCAP in and out: fast chunk decoding with a robust fallback, message paths, time bases
and resampling onto a uniform grid, converters (CSV, MAT, UFF 58).

Importing this package imports ``mcap``; the numerical core never imports it.
"""

from vibroscope.io.mcap_read import (
    LogInfo,
    TopicInfo,
    discover_fields,
    iter_raw_messages,
    mcap_info,
    read_mcap,
    select_acceleration_channels,
    unit_for,
)
from vibroscope.io.paths import MessagePath, get_field, parse_path
from vibroscope.io.timebase import TimebaseReport

__all__ = [
    "read_mcap",
    "mcap_info",
    "discover_fields",
    "select_acceleration_channels",
    "iter_raw_messages",
    "unit_for",
    "LogInfo",
    "TopicInfo",
    "TimebaseReport",
    "MessagePath",
    "parse_path",
    "get_field",
]
