"""/metrics is written as the strings it is made of: a large fleet's answer is never held whole.

At 10,000 robots the text is 170 MB and its gzip 17 MB; joining the pieces into one answer held it twice
over, in the exporter's process, at every scrape. A real server in this process answers a fleet of 800
robots x 50 components with its values; tracemalloc reads what the process allocated at most while it
answered, the client comparing each slice it reads with the assembler's text and keeping none.
"""

from __future__ import annotations

import http.client
import random
import tracemalloc
import zlib
from collections.abc import Iterator
from dataclasses import dataclass

import pytest

from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.ingest.payload import PayloadIngest
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.serve.assembler import WRITE_BYTES, coalesced
from overseer.serve.http import OverseerServer
from testbed.model_server import serving

ROBOTS = 800
COMPONENTS = 50
READ_BYTES = 1 << 16


@pytest.fixture(scope="module")
def server() -> Iterator[OverseerServer]:
    model = FleetModel(FleetLimits(max_robots=10_000, stale_after=3600, robot_timeout=3600))
    chance = random.Random(32)  # messages that compress as little as real ones: the gzip answer is large
    for robot in range(ROBOTS):
        name = f"site/robot{robot:04d}"
        statuses = tuple(
            DiagnosticStatus(
                (robot + index) % 3,
                f"/Sensors/Component {index}",
                f"reading {chance.randbytes(12).hex()}",
                f"hw{index}",
                (("temperature", f"{20 + (robot * index) % 50}.5"), ("voltage", "12.1")),
            )
            for index in range(COMPONENTS)
        )
        PayloadIngest(model, name, "dds", f"rt/{name}/diagnostics_agg", WIRE_FORMAT)(
            encode_diagnostic_array(DiagnosticArray(0, 0, "", statuses))
        )
    with serving(model) as server:
        yield server


@dataclass
class Scrape:
    """One scrape's answer as the client read it, and what this process allocated at most meanwhile."""

    length: int  # the answer's Content-Length
    received: int  # bytes read
    text_matches: bool  # the text (gunzipped when gzip) is the assembler's exposition, byte for byte
    most: int


def scraped(server: OverseerServer, use_gzip: bool) -> Scrape:
    """A scrape of `server`, its text compared a slice at a time: the client holds no copy of its own."""
    host, port = server.server_address[:2]
    connection = http.client.HTTPConnection(str(host), int(port), timeout=60)
    headers = {"Accept": "text/plain;version=0.0.4", **({"Accept-Encoding": "gzip"} if use_gzip else {})}
    expected = memoryview(server.assembler.assemble(server.fleet.exposition_parts()))
    reader = zlib.decompressobj(wbits=31)
    received = offset = 0
    matches = True
    tracemalloc.start()
    try:
        connection.request("GET", "/metrics", headers=headers)
        response = connection.getresponse()
        length = int(response.headers["Content-Length"])
        while chunk := response.read(READ_BYTES):
            received += len(chunk)
            text = reader.decompress(chunk) if use_gzip else chunk
            matches = matches and expected[offset : offset + len(text)] == text
            offset += len(text)
        _, most = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
        connection.close()
    return Scrape(length, received, matches and offset == len(expected), most)


def test_the_plain_answer_is_inflated_a_slice_at_a_time_never_held_whole(server: OverseerServer) -> None:
    scrape = scraped(server, use_gzip=False)
    assert scrape.received == scrape.length > 20_000_000
    assert scrape.text_matches
    # 0.23 times the answer here (the client's slices in it); inflated whole and joined, 2.1 times.
    most, length = scrape.most, scrape.length
    assert most < 0.6 * length, f"{most / 1e6:.1f} MB allocated for a {length / 1e6:.1f} MB answer"


def test_the_gzip_answer_is_the_same_text_in_one_member_never_joined(
    server: OverseerServer, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Its pieces are written as they are kept (tests/fleet/test_deflated.py checks none is copied).
    def joined(*_: object) -> bytes:
        raise AssertionError("the gzip answer was joined into one string")

    monkeypatch.setattr(server.assembler, "assemble_gzip", joined)
    scrape = scraped(server, use_gzip=True)
    assert scrape.received == scrape.length > 1_500_000  # runs of robots recompressed whole (joined_runs)
    assert scrape.text_matches


def test_short_strings_are_written_together_and_long_ones_as_they_are() -> None:
    long = bytes(WRITE_BYTES)
    strings = [b"a", b"bc", long, *(b"x" * 1000 for _ in range(70)), b"tail"]
    written = list(coalesced(strings))
    assert b"".join(written) == b"".join(strings)
    assert written[0] == b"abc"
    assert written[1] is long
    assert all(len(string) < 2 * WRITE_BYTES for string in written)
    assert len(written) == 4  # "abc", the long one, 66 short ones reaching WRITE_BYTES, the rest
