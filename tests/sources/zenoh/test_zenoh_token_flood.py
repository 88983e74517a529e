"""A flood of publisher tokens does not hold up the samples that come on the same link.

A fleet's tokens come at once: 20,000 of them when an exporter starts beside 10,000 robots, or when the
robots' router comes back. Each one's handling takes the interpreter lock, which a busy ingest holds for
milliseconds at a time. Handled in a callback, on the Zenoh thread that reads the link from the router,
they held that thread up, and the samples behind them waited, or were dropped by the router. They now
wait in a channel of their own. Here a real router, a robot session declaring 2,000 tokens at once, and a
token handler that takes 2 ms each (4 s for the flood): samples published meanwhile must still arrive at
once.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from overseer.config.zenoh import ZenohConfig
from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH, data_key, publisher_token
from overseer.sources.zenoh.receiver import ZenohReceiver
from testbed.processes import wait_for
from testbed.zenoh import client_session, endpoint, running_router

pytestmark = pytest.mark.servers

TOKENS = 2_000
TOKEN_SECONDS = 0.002  # what handling a token takes while the ingest is busy
SAMPLES = 50
SAMPLE_INTERVAL = 0.02


def test_samples_arrive_at_once_while_a_slowly_handled_flood_of_tokens_waits(tmp_path: Path) -> None:
    arrivals: dict[int, float] = {}
    tokens_handled = threading.Event()
    handled = 0

    def on_sample(key: str, attachment: bytes | None, payload: bytes) -> None:
        arrivals[int(payload)] = time.monotonic()

    def on_token(key: str, alive: bool) -> None:
        nonlocal handled
        time.sleep(TOKEN_SECONDS)
        handled += 1
        if handled == TOKENS:
            tokens_handled.set()

    with running_router(tmp_path) as port, client_session(port) as robot:
        receiver = ZenohReceiver(
            ZenohConfig(enabled=True, connect=(endpoint(port),)),
            on_sample,
            on_token,
            lambda: None,
            lambda: None,
        )
        receiver.start()
        try:
            key = data_key(0, "flooded", "diagnostics_agg")
            wait_for(lambda: robot.put(key, b"-1") or -1 in arrivals, 30, interval=0.2, message="heard")
            zid = str(robot.zid())
            declared = [
                robot.liveliness().declare_token(
                    publisher_token(
                        0, zid, index, f"robot{index}", "node", "diagnostics_agg", DIAGNOSTIC_ARRAY_HASH
                    )
                )
                for index in range(TOKENS)
            ]
            sent: dict[int, float] = {}
            for number in range(SAMPLES):
                sent[number] = time.monotonic()
                robot.put(key, str(number).encode())
                time.sleep(SAMPLE_INTERVAL)
            wait_for(lambda: len(arrivals) > SAMPLES, 30, message="every sample heard")
            assert not tokens_handled.is_set(), "the flood was handled before the samples: no test"
            delays = sorted(arrivals[number] - sent[number] for number in range(SAMPLES))
            assert delays[-1] < 0.5, f"samples waited behind the tokens: up to {delays[-1]:.2f} s"
            assert tokens_handled.wait(TOKENS * TOKEN_SECONDS * 5), "the tokens were not all handled"
            for token in declared:
                token.undeclare()  # type: ignore[no-untyped-call]
        finally:
            receiver.stop()
