"""The bridge's tokens are subscribed to once a bridge's sample is heard, and none declared before is missed.

A router serves every subscription of tokens as it serves another subscriber: a fleet of 10,000
rmw_zenoh robots starting at once lost 1.3-3.3 times as many updates at the router while the exporter
held a subscription to zenoh-bridge-ros2dds's tokens too, which no robot of that fleet declares. Here a real
router, an rmw_zenoh robot, and then a bridge whose token is declared before its first sample.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from overseer.config.zenoh import ZenohConfig
from overseer.sources.zenoh.keys import (
    BRIDGE,
    DIAGNOSTIC_ARRAY_HASH,
    RMW_ZENOH,
    bridge_key,
    bridge_liveliness_subscription,
    bridge_publisher_token,
    data_key,
    liveliness_subscription,
    publisher_token,
)
from overseer.sources.zenoh.receiver import ZenohReceiver
from testbed.processes import wait_for
from testbed.zenoh import client_session, endpoint, running_router

pytestmark = pytest.mark.servers


@pytest.mark.parametrize("buffered", [True, False], ids=["samples copied out", "samples handled at once"])
def test_the_bridges_tokens_are_subscribed_to_when_a_bridge_is_heard(tmp_path: Path, buffered: bool) -> None:
    heard: list[str] = []
    payloads: list[bytes] = []
    tokens: list[tuple[str, bool]] = []
    lock = threading.Lock()

    def on_sample(key: str, attachment: bytes | None, payload: bytes) -> None:
        with lock:
            heard.append(key)
            payloads.append(payload)

    def on_token(key: str, alive: bool) -> None:
        with lock:
            tokens.append((key, alive))

    with running_router(tmp_path) as port, client_session(port) as robot, client_session(port) as bridge:
        # Each format given twice: still one subscription of each, and each sample heard once.
        formats = (RMW_ZENOH, BRIDGE, RMW_ZENOH, BRIDGE)
        config = ZenohConfig(enabled=True, connect=(endpoint(port),), key_formats=formats)
        on_dropped = (lambda samples: None) if buffered else None
        receiver = ZenohReceiver(config, on_sample, on_token, lambda: None, lambda: None, on_dropped)
        receiver.start()
        try:
            zid = str(robot.zid())
            rmw_token = publisher_token(
                0, zid, 1, "robot1", "aggregator", "diagnostics_agg", DIAGNOSTIC_ARRAY_HASH
            )
            declared = robot.liveliness().declare_token(rmw_token)
            rmw_key = data_key(0, "robot1", "diagnostics_agg")
            wait_for(lambda: robot.put(rmw_key, b"1") or rmw_key in heard, 30, interval=0.2, message="heard")
            wait_for(lambda: (rmw_token, True) in tokens, 10, message="the rmw_zenoh token")
            # An rmw_zenoh fleet: one subscription of tokens, and no bridge's token asked for.
            assert receiver.token_subscriptions == [liveliness_subscription(0)]

            bridged_token = bridge_publisher_token(str(bridge.zid()), "amr1", "diagnostics_agg")
            bridge_declared = bridge.liveliness().declare_token(bridged_token)
            amr_key = bridge_key("amr1", "diagnostics_agg")
            wait_for(
                lambda: bridge.put(amr_key, b"1") or amr_key in heard, 10, interval=0.2, message="bridge"
            )
            # Declared before the bridge's first sample, and still heard: the subscription asks for history.
            wait_for(lambda: (bridged_token, True) in tokens, 10, message="the bridge's token")
            assert receiver.token_subscriptions == [
                liveliness_subscription(0),
                bridge_liveliness_subscription(),
            ]
            bridge_declared.undeclare()  # type: ignore[no-untyped-call]
            wait_for(lambda: (bridged_token, False) in tokens, 10, message="the bridge's token gone")
            bridge.put(amr_key, b"once")
            robot.put(rmw_key, b"once too")
            wait_for(lambda: b"once" in payloads and b"once too" in payloads, 10, message="the last samples")
            time.sleep(0.5)  # a second subscription's copies would have come by now
            assert (payloads.count(b"once"), payloads.count(b"once too")) == (1, 1)
            assert receiver.token_subscriptions.count(bridge_liveliness_subscription()) == 1
            declared.undeclare()  # type: ignore[no-untyped-call]
        finally:
            receiver.stop()
