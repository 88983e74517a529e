"""Deflated pieces: laid end to end they are one gzip answer, their checksums combine, bad data is refused."""

from __future__ import annotations

import importlib
import random
import threading
import tracemalloc
import zlib
from collections.abc import Callable, Iterator

import pytest

from overseer.fleet import deflated
from overseer.fleet.deflated import (
    Deflated,
    deflate,
    gzip_member,
    gzip_member_strings,
    inflate,
    inflate_in_slices,
    join,
)
from support.rendering import gunzip_one_member


def texts(count: int, seed: int = 7) -> list[bytes]:
    """Exposition-like lines and noise, one empty, some longer than the compressor's window."""
    chance = random.Random(seed)
    made = [b""]
    for index in range(count):
        lines = "".join(
            f'ros_diagnostics_level{{component="/c{n}",robot="robot{index}"}} {chance.randrange(4)}.0\n'
            for n in range(chance.randrange(0, 400))
        )
        made.append(lines.encode() + chance.randbytes(chance.randrange(0, 64)))
    return made


@pytest.fixture(params=["compiled", "python"])
def implementation(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """Each test on the compiled deflater and on Python's zlib module (the fallback)."""
    if request.param == "compiled":
        assert deflated.COMPILED, "the compiled deflater was not built (make setup builds it)"
    else:
        monkeypatch.setattr(deflated, "_deflate", deflated.deflate_in_python)
        monkeypatch.setattr(deflated, "_inflate", deflated.inflate_in_python)
        monkeypatch.setattr(deflated, "crc32_combine", deflated.crc32_combine_in_python)
    yield request.param


def test_pieces_laid_end_to_end_are_one_gzip_member_of_the_texts_joined(implementation: str) -> None:
    parts = texts(60)
    pieces = [deflate(text) for text in parts]
    assert all(inflate(piece) == text for piece, text in zip(pieces, parts, strict=True))
    body = gzip_member(pieces)
    assert gunzip_one_member(body) == b"".join(parts)
    whole = join(pieces)
    assert (whole.crc, whole.size) == (zlib.crc32(b"".join(parts)), len(b"".join(parts)))
    assert inflate(whole) == b"".join(parts)
    # Pieces joined are pieces again: a worker's families join into the assembler's answer.
    assert gunzip_one_member(gzip_member([join(pieces[:20]), join(pieces[20:])])) == b"".join(parts)


def test_a_piece_larger_than_the_scratch_buffer_round_trips(implementation: str) -> None:
    text = b"".join(texts(300, seed=5)) * 3
    assert len(text) > 2 << 20
    assert gunzip_one_member(gzip_member([deflate(b"head"), deflate(text), deflate(b"tail")])) == (
        b"head" + text + b"tail"
    )


@pytest.mark.parametrize(
    "arguments",
    [(1, 2, -5), (2**32, 0, 5), (0, 2**40, 5)],
    ids=["negative size", "crc1 over 32 bits", "crc2 over 32 bits"],
)
def test_the_compiled_combine_refuses_what_is_no_crc_or_size(arguments: tuple[int, int, int]) -> None:
    assert deflated.COMPILED
    with pytest.raises(ValueError, match="crc32_combine"):
        deflated.crc32_combine(*arguments)


@pytest.mark.parametrize("settings", [(2**32 + 1, 13, 5), (1, 16, 5), (1, 13, 0), (10, 13, 5)])
def test_the_compiled_deflater_refuses_settings_zlib_has_not(settings: tuple[int, int, int]) -> None:
    compiled = importlib.import_module("overseer.fleet._cdeflate")  # built by make setup
    with pytest.raises(ValueError, match="deflate: a setting from"):
        compiled.deflate(b"text", *settings)
    assert deflated._deflate(b"text") == deflated.deflate_in_python(b"text")  # and goes on as before


def test_a_piece_is_a_fraction_of_its_text() -> None:
    text = b"".join(texts(40))
    assert len(deflate(text).data) < len(text) / 4


def test_the_compiled_deflater_writes_what_pythons_zlib_module_does() -> None:
    assert deflated.COMPILED
    for text in texts(30, seed=3):
        if text:
            assert deflated._deflate(text) == deflated.deflate_in_python(text)


@pytest.mark.parametrize("size2", [0, 1, 4095, (1 << 20) + 17, 3 << 20])
def test_checksums_combine_as_zlib_computes_the_whole(size2: int) -> None:
    first, second = random.Random(size2).randbytes(1000), random.Random(-size2).randbytes(size2)
    crc1, crc2 = zlib.crc32(first), zlib.crc32(second)
    combined = zlib.crc32(first + second)
    assert deflated.crc32_combine_in_python(crc1, crc2, size2) == combined
    assert deflated.crc32_combine(crc1, crc2, size2) == combined


DAMAGES = pytest.mark.parametrize(
    "damage",
    [
        lambda piece: piece._replace(size=piece.size + 1),
        lambda piece: piece._replace(size=piece.size - 1),
        lambda piece: piece._replace(data=piece.data[:-9]),
        lambda piece: piece._replace(data=piece.data[:-4]),  # whole text, but no sync marker to join on
        lambda piece: piece._replace(data=zlib.compress(b"".join(texts(5)), 1, -15)),  # a final block
        lambda piece: piece._replace(data=b"\xff\xff\xff" + piece.data),
    ],
    ids=["claims more", "claims less", "cut short", "no sync marker", "final block", "not deflate"],
)


@DAMAGES
def test_a_piece_that_does_not_hold_its_length_is_refused(
    implementation: str, damage: Callable[[Deflated], Deflated]
) -> None:
    piece = deflate(b"".join(texts(5)))
    with pytest.raises(ValueError, match="inflate"):
        inflate(damage(piece))


@DAMAGES
def test_a_piece_inflated_in_slices_is_refused_as_whole(damage: Callable[[Deflated], Deflated]) -> None:
    piece = deflate(b"".join(texts(5)))
    assert piece.size > 256
    with pytest.raises(ValueError, match="inflate"):
        b"".join(inflate_in_slices(damage(piece), most=256))


def test_a_large_piece_is_inflated_in_slices_of_at_most_the_bound(implementation: str) -> None:
    text = b"".join(texts(300, seed=5)) * 3
    slices = list(inflate_in_slices(deflate(text), most=1 << 16))
    assert b"".join(slices) == text
    assert len(slices) >= len(text) >> 16
    assert max(map(len, slices)) <= 1 << 16
    assert list(inflate_in_slices(deflate(b"short"), most=1 << 16)) == [b"short"]


def test_a_large_piece_is_inflated_without_holding_its_text_or_a_copy_of_its_data() -> None:
    piece = deflate(b"".join(texts(300, seed=5)) * 8)
    assert len(piece.data) > 2 << 20
    tracemalloc.start()
    try:
        given = sum(len(text) for text in inflate_in_slices(piece, most=1 << 16))
        _, most = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert given == piece.size
    # Handing zlib what it left over each time copied the rest of the data: 2 copies at most alive.
    assert most < 1 << 20, f"{most / 1e6:.1f} MB allocated inflating {len(piece.data) / 1e6:.1f} MB of data"


def test_slices_of_no_bytes_are_refused() -> None:
    with pytest.raises(ValueError, match="at least one byte"):
        list(inflate_in_slices(deflate(b"text"), most=0))


def test_a_gzip_member_is_written_as_its_pieces_data_not_copied(implementation: str) -> None:
    pieces = [deflate(text) for text in texts(20)]
    strings = gzip_member_strings(pieces)
    assert b"".join(strings) == gzip_member(pieces)
    assert gunzip_one_member(b"".join(strings)) == b"".join(texts(20))
    kept = {id(piece.data) for piece in pieces if piece.size}
    assert kept <= {id(string) for string in strings}


def test_the_compiled_deflater_keeps_the_interpreter_lock_where_pythons_zlib_lets_go() -> None:
    # A scrape deflates thousands of pieces: letting go of the lock for each, beside a busy ingest
    # thread, waits for it again every time (seconds a scrape).
    text = b"".join(texts(400, seed=11)) * 8
    counted = [0]
    stop = threading.Event()

    def busy() -> None:
        while not stop.is_set():
            counted[0] += 1

    def others_progress(work: Callable[[], object]) -> int:
        before = counted[0]
        work()
        return counted[0] - before

    thread = threading.Thread(target=busy, daemon=True)
    thread.start()
    try:
        held = min(others_progress(lambda: deflated._deflate(text)) for _ in range(3))
        released = max(others_progress(lambda: deflated.deflate_in_python(text)) for _ in range(3))
    finally:
        stop.set()
        thread.join()
    # Held, the busy thread only runs in the one switch interval after the call; let go, all through it.
    assert released > 4 * held, (held, released)
