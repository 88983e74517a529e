"""A thread's scheduling priority lowered: the ingest yields a busy machine's cores to Zenoh's reading.

When a machine has no core to spare (a large fleet's first look, a router and a fleet beside the
exporter), the scheduler shares its cores out evenly, and Zenoh's threads that read the router's link get
no more than the ingest that is already seconds behind. The link then stalls and the router drops what it
cannot send, which nobody can read again. The ingest's thread lowered by a few nice levels gives those
threads the cores first: the samples wait in the exporter's own queue (`zenoh.queue_length`) and are
ingested as soon as there is room. On an idle machine a nice level changes nothing.
"""

from __future__ import annotations

import logging
import os
import sys
import threading

log = logging.getLogger(__name__)

LOWEST_PRIORITY = 19  # the highest nice value Linux has


def lower_thread_priority(steps: int) -> None:
    """Lower the calling thread's priority by `steps` nice levels (up to the lowest), on Linux; else nothing.

    Lowering is allowed to every process, so this needs no privilege. Where it fails all the same (a
    sandbox's seccomp filter), the thread goes on at its priority.
    """
    if steps <= 0 or sys.platform != "linux":
        return  # elsewhere PRIO_PROCESS with a thread's id is not the thread
    thread = threading.get_native_id()
    try:
        niceness = os.getpriority(os.PRIO_PROCESS, thread)
        os.setpriority(os.PRIO_PROCESS, thread, min(LOWEST_PRIORITY, niceness + steps))
    except OSError as error:
        log.warning("cannot lower the priority of thread %s: %s", threading.current_thread().name, error)
