"""MCAP chunk records opened: parsed without copying their data, their stated sizes checked
against the memory budget before anything is allocated, decompressed (zstd, LZ4) never beyond the
stated size, and their CRC-32 checked (ISA-L's when the ``isal`` package is installed, else
zlib's). Each thread reuses one decompression context and one output buffer."""

from __future__ import annotations

import os
import struct
import threading
import zlib
from pathlib import Path
from typing import Any

from mcap.records import Chunk

from vibroscope.errors import LogFormatError

MAX_CHUNK_USIZE = 1 << 32  # a stated uncompressed size beyond this is damage, not data
#: the largest ratio of a compressed chunk's stated uncompressed size to its compressed size (plus
#: :data:`RATIO_SLACK` bytes) that is decompressed; beyond it the chunk is refused as a lying size
#: or a decompression bomb. Real logs reach ~10 (zstd) and LZ4 frames cannot exceed ~255.
MAX_RATIO = 1000
RATIO_SLACK = 1 << 20
COMPRESSIONS = (b"", b"zstd", b"lz4")

try:  # optional codecs of mcap
    import zstandard as _zstd
except ImportError:  # pragma: no cover
    _zstd = None
try:
    import lz4.frame as _lz4
except ImportError:  # pragma: no cover
    _lz4 = None
try:  # LZ4 frames decompressed into a given buffer, with the GIL released (lz4's own API has no "into")
    from cramjam import lz4 as _cramjam_lz4
except ImportError:  # pragma: no cover - lz4.frame is the fallback
    _cramjam_lz4 = None
try:  # optional: CRC-32 of ISA-L, the same value as zlib's, several times faster
    from isal.isal_zlib import crc32
except ImportError:  # pragma: no cover - zlib's is the fallback
    crc32 = zlib.crc32


def memory_budget() -> int:
    """The default memory budget in bytes: half the available memory, or half the address-space
    limit (``ulimit -v``, ``RLIMIT_AS``), whichever is smaller.

    Returns
    -------
    int
    """
    avail = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            avail = 8 << 30
    budget = avail // 2
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY:
            budget = min(budget, soft // 2)
    except (ImportError, OSError, ValueError):
        pass
    return int(budget)


def check_chunk_size(chunk: Chunk, limit: int) -> None:
    """Refuse, before anything is allocated, a chunk whose stated uncompressed size exceeds
    `limit` bytes (a share of the memory budget), or :data:`MAX_RATIO` times its compressed size
    plus :data:`RATIO_SLACK`, or (uncompressed) differs from its data length.

    Parameters
    ----------
    chunk : mcap.records.Chunk
        The chunk record (its data not yet decompressed).
    limit : int
        Bytes one chunk may take decompressed.

    Raises
    ------
    ValueError
        Naming the stated size and the limit it exceeds.
    """
    usize, csize = chunk.uncompressed_size, len(chunk.data)
    if chunk.compression == "":
        if usize != csize:
            raise ValueError(f"uncompressed chunk states {usize} bytes but holds {csize}")
        return
    if usize > MAX_RATIO * csize + RATIO_SLACK:
        raise ValueError(f"stated uncompressed size {usize} exceeds {MAX_RATIO} times its {csize} compressed bytes "
                         f"(+{RATIO_SLACK}): a lying size or a decompression bomb, not decompressed")
    if usize > limit:
        raise ValueError(f"stated uncompressed size {usize} exceeds this chunk's share of the memory budget "
                         f"({limit} bytes; max_memory): not decompressed")


def read_chunk(mv: memoryview, body: int, end: int) -> Chunk:
    """Parse a Chunk record without copying its (possibly large) data."""
    if end - body < 40:
        raise ValueError(f"chunk record of {end - body} bytes is shorter than its fixed fields (40)")
    start_t, end_t, usize, crc, clen = struct.unpack_from("<QQQII", mv, body)
    if body + 40 + clen > end:
        raise ValueError(f"compression name length {clen} runs past the record end")
    if usize > MAX_CHUNK_USIZE:
        raise ValueError(f"uncompressed size {usize} is implausible")
    p = body + 32
    comp = bytes(mv[p : p + clen]).decode()
    p += clen
    (dlen,) = struct.unpack_from("<Q", mv, p)
    p += 8
    if p + dlen > end:
        raise ValueError(f"chunk data length {dlen} runs past the record end")
    return Chunk(compression=comp, data=mv[p : p + dlen], message_end_time=end_t, message_start_time=start_t,
                 uncompressed_crc=crc, uncompressed_size=usize)


_LOCAL = threading.local()


def decompress(chunk: Chunk) -> Any:
    """The chunk's data decompressed, never to more than its stated uncompressed size (a frame
    header claiming more is not believed: the output buffer is the stated size, filled by a
    stream; a frame that goes on beyond it raises)."""
    if chunk.compression == "":
        return chunk.data
    size = chunk.uncompressed_size
    if chunk.compression == "zstd":
        if _zstd is None:
            raise ValueError("zstd compression but the zstandard module is not installed")
        dec = getattr(_LOCAL, "zstd", None)
        if dec is None:  # one decompression context per thread, reused (zstandard objects are not thread-safe)
            dec = _LOCAL.zstd = _zstd.ZstdDecompressor()
        try:
            stated = _zstd.frame_content_size(chunk.data)  # the frame header's size, when it has one
        except Exception:  # noqa: BLE001 - not a zstd frame: the stream below names the fault
            stated = -1
        if stated == size:  # one call, into exactly the size already checked (zstd stops at the frame's size)
            return dec.decompress(chunk.data, max_output_size=size)
        if stated > size:
            raise ValueError(f"zstd frame states {stated} bytes, more than the {size} the chunk states: not "
                             f"decompressed")
        out = bytearray(size)
        got = zstd_stream_into(dec, chunk.data, memoryview(out))
        if got != size:
            raise ValueError(f"decompresses to more than the {size} bytes stated" if got > size else
                             f"decompresses to {got} bytes, not the {size} stated")
        return out
    if chunk.compression == "lz4":
        if _cramjam_lz4 is not None:
            out = bytearray(size)
            try:
                got = _cramjam_lz4.decompress_into(chunk.data, out)
            except Exception as exc:  # noqa: BLE001 - cramjam's errors: too long for the buffer, or damaged
                raise ValueError(f"LZ4 frame does not decompress into the {size} bytes stated ({exc})") from None
            if got != size:
                raise ValueError(f"decompresses to {got} bytes, not the {size} stated")
            return out
        if _lz4 is None:
            raise ValueError("lz4 compression but the lz4 module is not installed")
        d = _lz4.LZ4FrameDecompressor()
        out = d.decompress(bytes(chunk.data), max_length=size + 1)
        if len(out) != size or not d.eof:
            raise ValueError(f"decompresses to {'more than ' if len(out) > size else ''}{len(out)} bytes, not the "
                             f"{size} stated")
        return out
    raise ValueError(f"unsupported chunk compression {chunk.compression!r}")


def zstd_stream_into(dec: Any, data: Any, out: memoryview) -> int:
    """Decompress the zstd frame `data` into `out` by a stream (never more than ``len(out)`` + 1
    bytes produced); returns the bytes written, ``len(out) + 1`` when the frame goes on."""
    reader = dec.stream_reader(data, read_size=max(min(len(data), 1 << 20), 1), read_across_frames=False)
    size, got = len(out), 0
    while got < size:
        k = reader.readinto(out[got:])
        if not k:
            break
        got += k
    if got == size and reader.read(1):
        return size + 1
    return got


def _scratch(size: int) -> memoryview:
    """This thread's reused output buffer, at least `size` bytes (fresh pages for every chunk
    cost more than decompressing it)."""
    buf = getattr(_LOCAL, "buf", None)
    if buf is None or len(buf) < size:
        buf = _LOCAL.buf = bytearray(max(size, 1 << 20))
    return memoryview(buf)[:size]


def checked(chunk: Chunk, validate_crcs: bool = True) -> Any:
    """The chunk's data decompressed (:func:`decompress`), its size and (when stored and
    `validate_crcs`) its CRC-32 checked; raises ValueError naming the fault."""
    raw = decompress(chunk)
    if len(raw) != chunk.uncompressed_size:
        raise ValueError(f"uncompressed size {len(raw)} != {chunk.uncompressed_size} stated")
    if validate_crcs and chunk.uncompressed_crc != 0 and (crc := crc32(raw)) != chunk.uncompressed_crc:
        raise ValueError(f"CRC-32 mismatch: stored {chunk.uncompressed_crc:#010x}, computed {crc:#010x}")
    return raw


def decompress_into(chunk: Chunk) -> memoryview | None:
    """The chunk's data decompressed into this thread's reused buffer (a view of it, valid until
    the thread's next chunk), or None where that does not apply (then :func:`decompress`, which
    also gives the error of a damaged chunk)."""
    size = chunk.uncompressed_size
    try:
        if chunk.compression == "zstd" and _zstd is not None:
            out = _scratch(size)
            dec = getattr(_LOCAL, "zstd", None)
            if dec is None:
                dec = _LOCAL.zstd = _zstd.ZstdDecompressor()
            return out if zstd_stream_into(dec, chunk.data, out) == size else None
        if chunk.compression == "lz4" and _cramjam_lz4 is not None:
            out = _scratch(size)
            return out if _cramjam_lz4.decompress_into(chunk.data, out) == size else None
    except Exception:  # noqa: BLE001 - the usual path decides (and names the fault)
        return None
    return None


def release_scratch() -> None:
    """Drop this thread's reused output buffer (:func:`decompress_into`); its decompression context stays."""
    _LOCAL.__dict__.pop("buf", None)


def reopen_chunk(mview: memoryview, path: Path, pos: int, end: int, validate_crcs: bool) -> Any:
    """The bytes of the chunk record at `pos` again (it was read whole and valid before)."""
    try:
        chunk = read_chunk(mview, pos + 9, end)
        raw = decompress(chunk)
    except Exception as exc:  # noqa: BLE001 - only VibroscopeError escapes
        raise LogFormatError(f"{path}: chunk at byte offset {pos} no longer decompresses ({type(exc).__name__}: "
                             f"{exc}); the file changed since it was scanned?") from exc
    if len(raw) != chunk.uncompressed_size or (
            validate_crcs and chunk.uncompressed_crc != 0 and crc32(raw) != chunk.uncompressed_crc):
        raise LogFormatError(f"{path}: chunk at byte offset {pos} no longer matches its size and CRC-32; the file "
                             f"changed since it was scanned?")
    return raw

