"""What marks a file as written by vibroscope, and the test of it (:func:`written_by_vibroscope`).

An output path that exists is replaced only when it is a regular file that vibroscope wrote
(:mod:`vibroscope.commands._outputs`); anything else is refused, named, before any work. Each
format carries its mark where the format's readers ignore it, and the test reads at most the
first :data:`HEAD_BYTES` bytes of a file:

=======  ==========================================================================================
format   mark
=======  ==========================================================================================
MCAP     the Header record's ``library`` begins with ``vibroscope`` (:mod:`vibroscope.io.mcap_write`)
RRD      rerun's ``RRF`` magic, and the recording's application id (``vibroscope``...) in the
         first :data:`HEAD_BYTES` bytes (rerun writes its store info first, uncompressed)
PNG      a ``tEXt`` chunk ``Software`` = :data:`GENERATOR` before the image data
JSON     the first key: ``"generator": "vibroscope <version>"`` (:func:`json_report`)
TOML     the first line ``# generator: vibroscope <version>`` (:func:`toml_header`)
UFF      a dataset 151 (header) first, its creating program :data:`GENERATOR`
         (:func:`uff_header`); or the dataset-55 ID line 2 ``vibroscope mode shapes``
CSV      the fleet table's header (:meth:`vibroscope.fleet.FleetResult.write_csv`):
         ``log,n_samples,duration_s,modes_hz,damping,`` (a CSV has no place for a mark
         that every CSV reader ignores)
=======  ==========================================================================================

This module imports nothing of vibroscope's but its version.
"""

from __future__ import annotations

import os
import re
import time
from typing import Any, Mapping

from vibroscope import __version__

__all__ = ["GENERATOR", "HEAD_BYTES", "FLEET_CSV_HEADER", "written_by_vibroscope", "json_report", "toml_header",
           "uff_header"]

#: who wrote an output, as every mark states it
GENERATOR = f"vibroscope {__version__}"
#: the most bytes :func:`written_by_vibroscope` reads of a file
HEAD_BYTES = 65536

_MCAP_MAGIC = b"\x89MCAP0\r\n"
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_JSON_MARK = re.compile(rb'\A\s*\{\s*"generator"\s*:\s*"vibroscope\b')
_TOML_MARK = re.compile(rb"\A# generator: vibroscope\b")
#: the first columns of the fleet table (:meth:`vibroscope.fleet.FleetResult.write_csv`)
FLEET_CSV_HEADER = b"log,n_samples,duration_s,modes_hz,damping,"


def json_report(doc: Mapping[str, Any]) -> dict[str, Any]:
    """`doc` with ``"generator": GENERATOR`` as its first key (the other keys as they were).

    Parameters
    ----------
    doc : mapping
        A JSON report's top level.

    Returns
    -------
    dict
    """
    return {"generator": GENERATOR, **{k: v for k, v in doc.items() if k != "generator"}}


def toml_header() -> str:
    """The first line of a TOML file vibroscope writes: ``# generator: vibroscope <version>``.

    Returns
    -------
    str
        One line, newline-terminated (a TOML comment: readers ignore it).
    """
    return f"# generator: {GENERATOR}\n"


def uff_header() -> str:
    """A Universal File dataset 151 (header) naming vibroscope as the program that wrote the file.

    Returns
    -------
    str
        The record, ``-1`` delimited, to put before the file's other datasets (readers of UFF
        skip or read dataset 151; :func:`vibroscope.io.frf_files.read_frf` and its siblings read
        the datasets they need).

    References
    ----------
    .. [1] Structural Dynamics Research Lab., "Universal File Datasets Summary", dataset 151
       (Header), University of Cincinnati.
    """
    now = time.strftime("%d-%b-%y %H:%M:%S")
    lines = ["    -1", "   151", "NONE", "NONE", GENERATOR, f"{now}           0         0         0",
             f"{now}", GENERATOR, f"{now}", "    -1"]
    return "\n".join(ln.ljust(80) if i not in (0, 5, 9) else ln for i, ln in enumerate(lines)) + "\n"


def _mcap_library(head: bytes) -> bytes | None:
    """The ``library`` string of an MCAP Header record at the start of `head`, or None."""
    if not head.startswith(_MCAP_MAGIC) or head[8:9] != b"\x01" or len(head) < 21:
        return None
    body = head[17:17 + int.from_bytes(head[9:17], "little")]
    n = int.from_bytes(body[0:4], "little")
    if len(body) < 8 + n:
        return None
    m = int.from_bytes(body[4 + n:8 + n], "little")
    lib = body[8 + n:8 + n + m]
    return lib if len(lib) == m else None


def _png_software(head: bytes) -> bytes | None:
    """The ``Software`` text of a PNG (``tEXt`` chunks before the first ``IDAT``), or None."""
    if not head.startswith(_PNG_MAGIC):
        return None
    i = len(_PNG_MAGIC)
    while i + 8 <= len(head):
        n = int.from_bytes(head[i:i + 4], "big")
        kind = head[i + 4:i + 8]
        if kind in (b"IDAT", b"IEND"):
            return None
        if kind == b"tEXt":
            key, _, val = head[i + 8:i + 8 + n].partition(b"\0")
            if key == b"Software":
                return val
        i += 12 + n
    return None


def written_by_vibroscope(path: str | os.PathLike) -> bool:
    """Whether `path` is a regular file that vibroscope wrote (it carries a mark of the module's table).

    Parameters
    ----------
    path : str or path-like
        The file. A symbolic link, FIFO, device or folder is never one (it is not opened: a
        FIFO would block).

    Returns
    -------
    bool
        False also when the file cannot be read.
    """
    import stat

    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return False
        with open(path, "rb") as fh:
            head = fh.read(HEAD_BYTES)
    except (OSError, ValueError):
        return False
    if head.startswith(_MCAP_MAGIC):
        lib = _mcap_library(head)
        return lib is not None and lib.startswith(b"vibroscope")
    if head.startswith(b"RRF"):
        return b"vibroscope" in head
    if head.startswith(_PNG_MAGIC):
        sw = _png_software(head)
        return sw is not None and sw.startswith(b"vibroscope")
    if _JSON_MARK.match(head) or _TOML_MARK.match(head) or head.startswith(FLEET_CSV_HEADER):
        return True
    lines = head[:2048].splitlines()
    if len(lines) >= 5 and lines[0].strip() == b"-1":  # a Universal File: our 151 header, or UFF 55's ID line 2
        if lines[1].strip() == b"151":
            return lines[4].strip().startswith(b"vibroscope") or lines[7].strip().startswith(b"vibroscope")
        if lines[1].strip() == b"55":
            return lines[3].strip() == b"vibroscope mode shapes"
    return False
