"""Exceptions raised by vibroscope.

Every I/O or format fault raises a :class:`VibroscopeError` subclass whose message names
the file, topic, field or byte offset at fault.
"""

from __future__ import annotations

__all__ = ["VibroscopeError", "LogFormatError", "ChannelError", "ModelFileError"]


class VibroscopeError(Exception):
    """Base class of every vibroscope I/O, format or model-file error.

    See Also
    --------
    LogFormatError, ChannelError, ModelFileError : The faults it groups.

    Examples
    --------
    A file that is not an MCAP log, named with the byte offset at fault:

    >>> import pathlib, tempfile
    >>> from vibroscope import read_mcap
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = pathlib.Path(d) / "notes.mcap"
    ...     _ = path.write_text("not a log")
    ...     try:
    ...         read_mcap(path)
    ...     except VibroscopeError as exc:
    ...         print(type(exc).__name__, str(exc).split(": ", 1)[1])
    LogFormatError not an MCAP file (bad magic at byte offset 0)
    """


class LogFormatError(VibroscopeError):
    """A log file is damaged or not in a supported format (names file and byte offset).

    See Also
    --------
    VibroscopeError : The base of every fault the package raises.
    ChannelError : A channel absent from a log or not decodable.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from vibroscope.io import LogIndex
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = pathlib.Path(d) / "empty.mcap"
    ...     _ = path.write_bytes(b"")
    ...     try:
    ...         LogIndex.open(path)
    ...     except LogFormatError as exc:
    ...         print("empty.mcap" in str(exc))
    True
    """


class ChannelError(VibroscopeError, KeyError):
    """A requested channel (message path) is absent or cannot be decoded (names topic and field).

    Also a :class:`KeyError`, as a missing key of a mapping.

    See Also
    --------
    VibroscopeError : The base of every fault the package raises.
    LogFormatError : A damaged log or one in an unsupported format.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> from vibroscope import Signals, read_mcap
    >>> from vibroscope.io import write_ros2_mcap
    >>> sig = Signals(data=np.zeros((1, 100)), fs=100.0, channels=["/imu.linear_acceleration.z"])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     log = write_ros2_mcap(pathlib.Path(d) / "run.mcap", sig)
    ...     try:
    ...         read_mcap(log, ["/imu.linear_acceleration.w"])
    ...     except KeyError as exc:
    ...         print(type(exc).__name__, "topic '/imu'" in str(exc), "/imu.linear_acceleration.z" in str(exc))
    ChannelError True True
    """

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0]) if self.args else ""


class ModelFileError(VibroscopeError, ValueError):
    """A model file (TOML) is invalid: unknown key, missing DOF, non-physical value (names key and line).

    Also a :class:`ValueError`.

    See Also
    --------
    VibroscopeError : The base of every fault the package raises.
    vibroscope.load_model : Reads a model file and raises this error.

    Examples
    --------
    >>> from vibroscope.models.modelfile import loads_model
    >>> try:
    ...     loads_model("[[dof]]")
    ... except ValueError as exc:
    ...     print(type(exc).__name__, "missing required key 'kind'" in str(exc))
    ModelFileError True
    """
