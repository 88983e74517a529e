"""The Alertmanager client, in process, against a loopback port nothing listens on."""

from __future__ import annotations

import contextlib
import gc
import types

from overseer.config.alertmanager import AlertmanagerConfig
from overseer.push.alertmanager_client import AlertmanagerClient, AlertmanagerError
from testbed.ports import free_port


def test_an_alertmanager_that_does_not_answer_leaves_no_frame_of_the_client_in_a_cycle() -> None:
    client = AlertmanagerClient(AlertmanagerConfig(url=f"http://127.0.0.1:{free_port()}", timeout=5.0))
    gc.collect()
    gc.disable()
    gc.set_debug(gc.DEBUG_SAVEALL)  # what the collector finds unreachable is kept in gc.garbage to look at
    try:
        with contextlib.suppress(AlertmanagerError):
            client.silences()
        gc.collect()
        # urllib's own opener and handlers refer to each other, a cycle of its own each request; the
        # error's cause named by a local of the client's frame kept that frame and its callers' too.
        frames = [item.f_code.co_name for item in gc.garbage if isinstance(item, types.FrameType)]
    finally:
        gc.set_debug(0)
        gc.garbage.clear()
        gc.enable()
    assert "_request" not in frames and "silences" not in frames, frames
