"""The fleet as it should be: the robots listed, their labels, the components each must report.

An `Inventory` is read from the operator's file (`inventory/file.py`) and handed to the model, which keeps
every listed robot (heard or not) and shows each expected component a robot does not report as one of
its components, STALE, whose message says what is missing (`expected_components`). The records of a
listing (`ListedRobot`, `Expectation`) are the model's own, in `state`. Robots remembered from before a
restart come back with the components a clean stop kept (`restored_components`).
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from overseer.levels import Level
from overseer.model.component_keys import ComponentKeys
from overseer.model.state import (
    Component,
    ComponentKey,
    ListedRobot,
    RememberedComponent,
    RobotState,
)

# The feed of a component that stands for an expectation no reported component meets: no transport
# names a feed so (feeds are topics and publisher ids), and the model's judgements treat it as never
# updated.
EXPECTED_FEED = "\0expected"


@dataclass(frozen=True)
class Inventory:
    """Every listed robot by its exact name (a plain mapping, so that it pickles to the ingest workers)."""

    robots: Mapping[str, ListedRobot] = field(default_factory=dict)


def expected_components(
    listing: ListedRobot | None, components: Mapping[ComponentKey, Component], now: float
) -> dict[ComponentKey, Component]:
    """`components` with one STALE stand-in for each expectation of `listing` they do not meet.

    Stand-ins already there are kept as they are while their message holds, so that a robot's record
    changes only when what is missing does.
    """
    reported = {key: c for key, c in components.items() if c.feed != EXPECTED_FEED}
    if listing is None or not listing.expected:
        return reported
    result = dict(reported)
    for expectation in listing.expected:
        count = sum(1 for name, _ in reported if expectation.matches(name))
        if count >= expectation.at_least:
            continue
        key = (expectation.shown_as, "")
        if key in reported:  # a reported component bears the name the stand-in would: it speaks for itself
            continue
        message = expectation.unmet_message(count)
        old = components.get(key)
        if old is not None and old.feed == EXPECTED_FEED and old.message == message:
            result[key] = old
        else:
            result[key] = Component(key, Level.STALE, message, "", (), now, 0, EXPECTED_FEED)
    return result


def is_stand_in(component: Component) -> bool:
    """True for a component that stands for an unmet expectation, not one a robot reported."""
    return component.feed == EXPECTED_FEED


def listed_state(state: RobotState, listing: ListedRobot | None, now: float) -> RobotState:
    """`state` with `listing` as its entry of the inventory, and the stand-ins its expectations need."""
    components = expected_components(listing, state.components, now)
    return state._replace(
        listing=listing, components=MappingProxyType(components), revision=state.revision + 1
    )


def restored_components(
    remembered: Iterable[RememberedComponent], last: float, keys: ComponentKeys
) -> dict[ComponentKey, Component]:
    """Components remembered from before a restart, as last reported at `last` (on no feed of this run).

    Their keys are the model's shared ones (`keys`): a component reported again keeps the key it had.
    """
    restored: dict[ComponentKey, Component] = {}
    intern = sys.intern
    for name, hardware_id, level, message in remembered:
        key = keys.of(intern(name))
        if key not in restored and 0 <= level <= 3:
            restored[key] = Component(
                key, _LEVELS[level], intern(message), intern(hardware_id), (), last, 0, ""
            )
    return restored


_LEVELS = tuple(Level)
