"""A large `/metrics` answer, once written, is followed by a trim of the exporter's heap.

At 10,000 robots the blocks of a scrape's parts (each worker's answer, read and unpickled) stayed on the
exporter's heap, 40 MB of them, until the minute's trim: the resident memory a scrape leaves behind.
A real server in this process answers; glibc's trim is recorded instead of made.
"""

from __future__ import annotations

import http.client
from collections.abc import Iterator

import pytest

from overseer import heap_trim
from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.ingest.payload import PayloadIngest
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.serve.http import OverseerServer
from testbed.model_server import serving


@pytest.fixture(scope="module")
def server() -> Iterator[OverseerServer]:
    model = FleetModel(FleetLimits(max_robots=100, stale_after=3600, robot_timeout=3600))
    for robot in range(5):
        name = f"robot{robot}"
        statuses = tuple(DiagnosticStatus(robot % 3, f"/Sensors/part{i}", "ok", "", ()) for i in range(10))
        PayloadIngest(model, name, "dds", f"rt/{name}/diagnostics_agg", WIRE_FORMAT)(
            encode_diagnostic_array(DiagnosticArray(0, 0, "", statuses))
        )
    with serving(model) as server:
        yield server


def trims_after_scrapes(
    server: OverseerServer, gzip: bool, monkeypatch: pytest.MonkeyPatch
) -> tuple[int, int]:
    """A scrape's answer length and how many trims followed it (a second request on its connection after)."""
    trims: list[int] = []

    def trim(pad: int) -> int:
        trims.append(pad)
        return 1

    monkeypatch.setattr(heap_trim, "_TRIM", trim)
    host, port = server.server_address[:2]
    connection = http.client.HTTPConnection(str(host), int(port), timeout=30)
    headers = {"Accept-Encoding": "gzip"} if gzip else {}
    try:
        connection.request("GET", "/metrics", headers=headers)
        response = connection.getresponse()
        length = len(response.read())
        assert response.status == 200 and length == int(response.headers["Content-Length"])
        # The connection's thread serves the next request once done with the first, its trim included.
        connection.request("HEAD", "/-/healthy")
        connection.getresponse().read()
        return length, len(trims)
    finally:
        connection.close()


@pytest.mark.parametrize("gzip", [False, True], ids=["text", "gzip"])
def test_an_answer_as_large_as_the_bound_is_followed_by_one_trim_a_smaller_one_by_none(
    server: OverseerServer, gzip: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    length, _ = trims_after_scrapes(server, gzip, monkeypatch)
    monkeypatch.setattr(heap_trim, "TRIM_AFTER_ANSWER_BYTES", length)
    assert trims_after_scrapes(server, gzip, monkeypatch) == (length, 1)
    monkeypatch.setattr(heap_trim, "TRIM_AFTER_ANSWER_BYTES", length + 1)
    assert trims_after_scrapes(server, gzip, monkeypatch) == (length, 0)
