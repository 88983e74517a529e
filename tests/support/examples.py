"""How many examples a property test draws: all of them in `make test`, a quarter in `make test-quick`."""

from __future__ import annotations

import os

QUICK = os.environ.get("OVERSEER_TEST_QUICK") == "1"


def examples(full: int) -> int:
    """`full` examples, or a quarter of them (at least 20) in the quick tier (OVERSEER_TEST_QUICK=1)."""
    return max(20, full // 4) if QUICK else full
