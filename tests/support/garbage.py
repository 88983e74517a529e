"""What a failure leaves in reference cycles: the exporter's collector runs seldom, and they wait for it."""

from __future__ import annotations

import gc
from collections.abc import Callable

import pytest


def left_in_cycles(act: Callable[[], object], failure: type[BaseException]) -> list[object]:
    """The objects `act` left unreachable in reference cycles; it must raise `failure` (caught here).

    What a cycle holds stays until the collector runs, which in the exporter is seldom
    (`garbage_collection`): a failure's frames, with whatever they named, for the rest of a run.
    """
    gc.collect()
    gc.disable()
    gc.set_debug(gc.DEBUG_SAVEALL)  # what the collector finds unreachable is kept in gc.garbage to look at
    try:
        with pytest.raises(failure):  # an act that did not fail would leave nothing, and prove nothing
            act()
        gc.collect()
        return list(gc.garbage)
    finally:
        gc.set_debug(0)
        gc.garbage.clear()
        gc.enable()
