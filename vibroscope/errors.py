"""Exceptions raised by vibroscope.

Every I/O or format fault raises a :class:`VibroscopeError` subclass whose message names
the file, topic, field or byte offset at fault.
"""

from __future__ import annotations

__all__ = ["VibroscopeError", "LogFormatError", "ChannelError", "ModelFileError"]


class VibroscopeError(Exception):
    """Base class of every vibroscope I/O, format or model-file error."""


class LogFormatError(VibroscopeError):
    """A log file is damaged or not in a supported format (names file and byte offset)."""


class ChannelError(VibroscopeError, KeyError):
    """A requested channel (message path) is absent or cannot be decoded (names topic and field)."""

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0]) if self.args else ""


class ModelFileError(VibroscopeError, ValueError):
    """A model file (TOML) is invalid: unknown key, missing DOF, non-physical value (names key and line)."""
