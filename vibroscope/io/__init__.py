"""MCAP in and out: fast chunk decoding with a robust fallback, message paths, time bases
and resampling onto a uniform grid, converters (CSV, MAT, UFF 58), FRF files
(UFF 58, complex CSV, pyuff text), mode shapes (UFF 55) and geometry (UFF 15 / 2411).

Importing this package imports ``mcap``; the numerical core never imports it.
"""

from vibroscope.io.mcap_read import (
    LogIndex,
    LogInfo,
    TopicInfo,
    discover_fields,
    iter_raw_messages,
    mcap_info,
    read_mcap,
    select_acceleration_channels,
    unit_for,
)
from vibroscope.io.convert import convert_to_mcap, read_csv, read_mat, read_uff58
from vibroscope.io.frf_files import (
    read_frf,
    read_geometry,
    read_modes_uff55,
    write_frf_uff58,
    write_geometry_uff15,
    write_modes_uff55,
)
from vibroscope.io.mcap_write import write_json_mcap, write_ros2_mcap
from vibroscope.io.paths import MessagePath, get_field, parse_path
from vibroscope.io.timebase import TimebaseReport

__all__ = [
    "read_frf",
    "write_frf_uff58",
    "read_modes_uff55",
    "write_modes_uff55",
    "read_geometry",
    "write_geometry_uff15",
    "read_mcap",
    "LogIndex",
    "mcap_info",
    "discover_fields",
    "select_acceleration_channels",
    "iter_raw_messages",
    "write_ros2_mcap",
    "write_json_mcap",
    "read_csv",
    "read_mat",
    "read_uff58",
    "convert_to_mcap",
    "unit_for",
    "LogInfo",
    "TopicInfo",
    "TimebaseReport",
    "MessagePath",
    "parse_path",
    "get_field",
]
