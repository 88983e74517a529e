"""The fleet as it should be: the robots listed, their labels, the components each must report.

An `Inventory` is read from the operator's file (`inventory/file.py`) and handed to the model, which keeps
every listed robot (heard or not) and shows each expected component a robot does not report as one of
its components, STALE, whose message says what is missing (`expected_components`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from overseer.levels import Level
from overseer.model.state import Component, ComponentKey

# The feed of a component that stands for an expectation no reported component meets: no transport
# names a feed so (feeds are topics and publisher ids), and the model's judgements treat it as never
# updated.
EXPECTED_FEED = "\0expected"
UNREPORTED = "expected, not reported"


@dataclass(frozen=True, slots=True)
class Expectation:
    """Components a robot must report: one by its exact name, or `at_least` matching a prefix or regex."""

    shown_as: str  # the component that stands for it while unmet: the name, 'prefix*' or the regex
    exact: str = ""
    prefix: str = ""
    pattern: re.Pattern[str] | None = None
    at_least: int = 1

    def matches(self, name: str) -> bool:
        """True when a component called `name` counts towards this expectation."""
        if self.pattern is not None:
            return self.pattern.fullmatch(name) is not None
        if self.prefix:
            return name.startswith(self.prefix)
        return name == self.exact

    def unmet_message(self, reported: int) -> str:
        """What the component standing for this expectation says, with `reported` matching components."""
        if self.exact:
            return UNREPORTED
        what = f"matching {self.prefix}*" if self.prefix else f"matching {self.shown_as}"
        return f"expected at least {self.at_least} components {what}, {reported or 'none'} reported"


@dataclass(frozen=True, slots=True)
class ListedRobot:
    """A robot of the inventory: its labels (sorted by name) and the components it must report."""

    labels: tuple[tuple[str, str], ...] = ()
    expected: tuple[Expectation, ...] = ()

    def expects(self, name: str) -> bool:
        """True when a component called `name` is one this robot must report."""
        return any(expectation.matches(name) for expectation in self.expected)


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
