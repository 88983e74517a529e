"""What a failure leaves in reference cycles: the exporter's collector runs seldom, and they wait for it."""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Callable


def left_in_cycles(act: Callable[[], object], failure: type[BaseException]) -> list[object]:
    """The objects `act` (raising `failure`, caught here) left unreachable in reference cycles.

    What a cycle holds stays until the collector runs, which in the exporter is seldom
    (`garbage_collection`): a failure's frames, with whatever they named, for the rest of a run.
    """
    gc.collect()
    gc.disable()
    gc.set_debug(gc.DEBUG_SAVEALL)  # what the collector finds unreachable is kept in gc.garbage to look at
    try:
        with contextlib.suppress(failure):
            act()
        gc.collect()
        return list(gc.garbage)
    finally:
        gc.set_debug(0)
        gc.garbage.clear()
        gc.enable()
