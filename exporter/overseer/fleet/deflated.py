"""Text kept compressed in pieces that join into one gzip answer without being compressed again.

A piece is raw deflate from a compressor of its own, ended by a sync flush: it refers to nothing before
it and stops on a byte boundary with a block that is not the last, so pieces laid end to end are one
valid deflate stream. With each piece's CRC-32 and length, their checksums combine into the gzip
trailer's. The exposition keeps every robot's lines this way: a scrape copies the compressed bytes of the
robots that did not change instead of compressing the whole answer again, and the cache holds a fraction
of the text's memory.

The work is done by `_cdeflate` (C, with zlib) where it was built: Python's zlib module lets go of the
interpreter lock around every call, and beside a busy thread each of a scrape's thousands of small calls
then waits for it again. Without the extension, Python's zlib module does the same, more slowly.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable, Iterable, Iterator
from typing import NamedTuple

try:
    from overseer.fleet import _cdeflate
except ImportError:  # installed without a C compiler
    _cdeflate = None  # type: ignore[assignment]

LEVEL = 1  # what the whole answer was gzipped at before: speed over the last few per cent
# A robot's family of lines is a few kilobytes: an 8 kB window compresses it as well as 32 kB, and the
# smaller compressor state is set up four times faster (it is set up for every piece).
WINDOW_BITS = 13
MEMORY_LEVEL = 5
_GZIP_HEADER = b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\xff"  # deflate, no name, no time, unknown system
_LAST_BLOCK = zlib.compressobj(LEVEL, zlib.DEFLATED, -WINDOW_BITS).flush()  # an empty final block
_TRAILER = struct.Struct("<II")
# A piece is inflated this much at a time when its text is to be written out rather than kept: a worker's
# family of lines at 10,000 robots is tens of megabytes of text.
SLICE_BYTES = 1 << 20
_FEED_BYTES = 1 << 16  # a large piece's data handed to zlib at a time: zlib copies what it leaves over


class Deflated(NamedTuple):
    """`size` bytes of text whose CRC-32 is `crc`, as raw deflate `data` ending in a sync flush."""

    data: bytes
    crc: int
    size: int


EMPTY = Deflated(b"", 0, 0)


def deflate(text: bytes) -> Deflated:
    """`text` as a piece of its own."""
    if not text:
        return EMPTY
    data, crc = _deflate(text)
    return Deflated(data, crc, len(text))


def join(pieces: Iterable[Deflated]) -> Deflated:
    """The pieces, in order, as one piece (no byte is compressed again)."""
    data, crc, size = _laid_end_to_end(pieces)
    return Deflated(b"".join(data), crc, size)


def _laid_end_to_end(pieces: Iterable[Deflated]) -> tuple[list[bytes], int, int]:
    """The pieces' data in order (empty pieces left out), and the CRC-32 and length of their texts."""
    data: list[bytes] = []
    crc = size = 0
    combine = crc32_combine
    for piece in pieces:
        if piece.size:
            data.append(piece.data)
            crc = combine(crc, piece.crc, piece.size)
            size += piece.size
    return data, crc, size


def inflate(piece: Deflated) -> bytes:
    """The text of `piece`; ValueError when its data does not give back its length, or would not join."""
    return _inflate(piece.data, piece.size) if piece.size else b""


def gzip_member(pieces: Iterable[Deflated]) -> bytes:
    """The pieces' text, in order, as one gzip member (what a `Content-Encoding: gzip` body is)."""
    return b"".join(gzip_member_strings(pieces))


def gzip_member_strings(pieces: Iterable[Deflated]) -> list[bytes]:
    """`gzip_member(pieces)` as the byte strings it is made of, in order: the pieces' data not copied."""
    data, crc, size = _laid_end_to_end(pieces)
    return [_GZIP_HEADER, *data, _LAST_BLOCK, _TRAILER.pack(crc, size & 0xFFFFFFFF)]


def inflate_in_slices(piece: Deflated, most: int = SLICE_BYTES) -> Iterator[bytes]:
    """The text of `piece` in slices of at most `most` bytes, for writing out; ValueError as `inflate`.

    A piece of `most` bytes of text or less is inflated at once (checked before its text is given); a
    larger one a slice at a time from its data read 64 kB at a time, and checked as its last slice is
    read: neither its text nor a copy of its data is ever held whole, and what was given before a
    damage is found stays given.
    """
    if most <= 0:
        raise ValueError(f"inflate: slices of at least one byte, not {most}")
    if piece.size <= most:
        yield inflate(piece)
        return
    reader = zlib.decompressobj(-zlib.MAX_WBITS)
    data = memoryview(piece.data)
    given = 0
    try:
        for start in range(0, len(data), _FEED_BYTES):
            pending: bytes | memoryview = data[start : start + _FEED_BYTES]
            while True:
                # Zlib keeps what did not fit in `most` for the next call, even of no more data.
                text = reader.decompress(pending, most)
                pending = reader.unconsumed_tail
                given += len(text)
                if given > piece.size:
                    raise ValueError(f"inflate: the data holds more than the {piece.size} bytes it should")
                if text:
                    yield text
                if not pending and len(text) < most:
                    break
    except zlib.error as error:
        raise ValueError(f"inflate: {error}") from None
    _refuse_unless_whole(given, piece.size, reader, piece.data)


def deflate_in_python(text: bytes) -> tuple[bytes, int]:
    """`_cdeflate.deflate`'s raw deflate and CRC-32 of `text`, by Python's zlib module."""
    compressor = zlib.compressobj(LEVEL, zlib.DEFLATED, -WINDOW_BITS, MEMORY_LEVEL)
    return compressor.compress(text) + compressor.flush(zlib.Z_SYNC_FLUSH), zlib.crc32(text)


def inflate_in_python(data: bytes, size: int) -> bytes:
    """`_cdeflate.inflate` by Python's zlib module."""
    reader = zlib.decompressobj(-zlib.MAX_WBITS)
    try:
        text = reader.decompress(data, size + 1)
    except zlib.error as error:
        raise ValueError(f"inflate: {error}") from None
    _refuse_unless_whole(len(text), size, reader, data)
    return text


def _refuse_unless_whole(given: int, size: int, reader: zlib._Decompress, data: bytes) -> None:
    """ValueError unless `reader` gave all `size` bytes of `data`'s text, and the piece would join."""
    # Whole, and joinable: no final block, and ending in a sync flush's empty stored block.
    if given != size or reader.eof or reader.unconsumed_tail or not data.endswith(_SYNC_MARKER):
        raise ValueError(f"inflate: the data does not hold the {size} bytes of text it should")


_SYNC_MARKER = b"\x00\x00\xff\xff"


_ZEROS = memoryview(bytes(1 << 20))


def crc32_combine_in_python(crc1: int, crc2: int, size2: int) -> int:
    """Zlib's crc32_combine from `zlib.crc32` alone (linear in `size2`, where zlib's is logarithmic)."""
    # CRC-32 is affine: A+B's is A's run on over B's length of zeros, xor the zeros' own, xor B's.
    zeros_crc, run_on = 0, crc1
    while size2:
        step = min(size2, len(_ZEROS))
        zeros = _ZEROS[:step]
        run_on, zeros_crc = zlib.crc32(zeros, run_on), zlib.crc32(zeros, zeros_crc)
        size2 -= step
    return run_on ^ zeros_crc ^ crc2


def _deflate_compiled(text: bytes) -> tuple[bytes, int]:
    return _cdeflate.deflate(text, LEVEL, WINDOW_BITS, MEMORY_LEVEL)


COMPILED = _cdeflate is not None
_deflate = _deflate_compiled if COMPILED else deflate_in_python
_inflate: Callable[[bytes, int], bytes] = _cdeflate.inflate if COMPILED else inflate_in_python
crc32_combine: Callable[[int, int, int], int] = (
    _cdeflate.crc32_combine if COMPILED else crc32_combine_in_python
)
