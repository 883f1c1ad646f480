"""MCAP in and out: fast chunk decoding with a robust fallback, message paths, time bases
and resampling onto a uniform grid, converters (CSV, MAT, UFF 58), FRF files
(UFF 58, complex CSV, pyuff text), mode shapes (UFF 55) and geometry (UFF 15 / 2411), mode sets
(UFF 55, model files, MODES.json).

Importing this package imports ``mcap``; the numerical core never imports it. The file
converters and the FRF/UFF files (which use scipy and the modal room) load on first use, so
``vibroscope info LOG`` starts without them.
"""

from vibroscope._lazy import lazy_attributes
from vibroscope.io.mcap_read import (
    LogIndex,
    LogInfo,
    TopicInfo,
    discover_fields,
    iter_raw_messages,
    mcap_info,
    memory_budget,
    read_mcap,
    select_acceleration_channels,
    unit_for,
)
from vibroscope.io.mcap_write import write_json_mcap, write_ros2_mcap
from vibroscope.io.paths import MessagePath, get_field, parse_path
from vibroscope.io.timebase import TimebaseReport

__all__ = [
    "read_frf",
    "write_frf_uff58",
    "read_modes_uff55",
    "write_modes_uff55",
    "read_mode_set",
    "ModeSet",
    "read_geometry",
    "write_geometry_uff15",
    "read_mcap",
    "memory_budget",
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

#: names loaded on first use, by module
_LAZY = {
    "convert_to_mcap": "convert", "read_csv": "convert", "read_mat": "convert", "read_uff58": "convert",
    "read_frf": "frf_files", "read_geometry": "frf_files", "read_modes_uff55": "frf_files",
    "write_frf_uff58": "frf_files", "write_geometry_uff15": "frf_files", "write_modes_uff55": "frf_files",
    "read_mode_set": "mode_sets", "ModeSet": "mode_sets",
}


__getattr__, __dir__ = lazy_attributes(__name__, {k: f".{m}" for k, m in _LAZY.items()})
