"""The Alertmanager client, in process, against a loopback port nothing listens on."""

from __future__ import annotations

import types

from overseer.config.alertmanager import AlertmanagerConfig
from overseer.push.alertmanager_client import AlertmanagerClient, AlertmanagerError
from support.garbage import left_in_cycles
from testbed.ports import free_port


def test_an_alertmanager_that_does_not_answer_leaves_no_frame_of_the_client_in_a_cycle() -> None:
    client = AlertmanagerClient(AlertmanagerConfig(url=f"http://127.0.0.1:{free_port()}", timeout=5.0))
    # urllib's own opener and handlers refer to each other, a cycle of its own each request; the error's
    # cause named by a local of the client's frame kept that frame and its callers' too.
    garbage = left_in_cycles(client.silences, AlertmanagerError)
    frames = [item.f_code.co_name for item in garbage if isinstance(item, types.FrameType)]
    assert "_request" not in frames and "silences" not in frames, frames
