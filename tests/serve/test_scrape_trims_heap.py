"""A large `/metrics` answer, once written, is followed by a trim of the exporter's heap.

At 10,000 robots a scrape left 35-40 MB of freed blocks resident in the exporter's process until the
minute's trim.
A real server in this process answers; glibc's trim is recorded instead of made.
"""

from __future__ import annotations

import http.client
import threading
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
) -> tuple[int, list[bool]]:
    """A scrape's answer length, and for each trim made for it whether the client had read it all by then."""
    trims: list[bool] = []
    answered = threading.Event()

    def trim(pad: int) -> int:
        trims.append(answered.wait(5))  # a trim made before the answer was written would hold it back
        return 1

    monkeypatch.setattr(heap_trim, "_TRIM", trim)
    host, port = server.server_address[:2]
    connection = http.client.HTTPConnection(str(host), int(port), timeout=30)
    headers = {"Accept-Encoding": "gzip"} if gzip else {}
    try:
        connection.request("GET", "/metrics", headers=headers)
        response = connection.getresponse()
        length = len(response.read())
        answered.set()
        assert response.status == 200 and length == int(response.headers["Content-Length"])
        # The connection's thread serves the next request once done with the first, its trim included.
        connection.request("HEAD", "/-/healthy")
        connection.getresponse().read()
        return length, trims
    finally:
        connection.close()


@pytest.mark.parametrize("gzip", [False, True], ids=["text", "gzip"])
def test_an_answer_as_large_as_the_bound_is_followed_by_one_trim_a_smaller_one_by_none(
    server: OverseerServer, gzip: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    length, _ = trims_after_scrapes(server, gzip, monkeypatch)
    monkeypatch.setattr(heap_trim, "TRIM_AFTER_ANSWER_BYTES", length)
    assert trims_after_scrapes(server, gzip, monkeypatch) == (length, [True])
    monkeypatch.setattr(heap_trim, "TRIM_AFTER_ANSWER_BYTES", length + 1)
    assert trims_after_scrapes(server, gzip, monkeypatch) == (length, [])
