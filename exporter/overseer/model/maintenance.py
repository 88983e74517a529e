"""What a maintenance window is: the robots it covers, when, why and who said so; recurring ones too."""

from __future__ import annotations

import datetime
import re
from dataclasses import dataclass
from typing import Any
from zoneinfo import ZoneInfo

# A robot name as the transports make them (ROS names): segments of letters, digits and _, joined by /.
_NAME = re.compile(r"[A-Za-z0-9_]+(/[A-Za-z0-9_]+)*")
DAYS = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")


@dataclass(frozen=True)
class RobotSelector:
    """One robot by its exact name (`site_a/robot7`), or every robot under a namespace (`site_a/`)."""

    text: str

    @property
    def prefix(self) -> bool:
        """True for a namespace prefix (it ends in `/`)."""
        return self.text.endswith("/")

    def matches(self, robot: str) -> bool:
        """True when the window covers `robot`."""
        return robot.startswith(self.text) if self.prefix else robot == self.text

    @staticmethod
    def parse(value: object) -> RobotSelector:
        """A selector from its text (a leading `/` is dropped); ValueError saying what it may hold."""
        text = value.strip() if isinstance(value, str) else ""
        name = text.strip("/")
        if not name or len(name) > 256 or not _NAME.fullmatch(name):
            raise ValueError(
                "expected a robot name (letters, digits and _ in segments joined by /) or a namespace prefix "
                f"ending in / such as site_a/, got {value!r}"
            )
        return RobotSelector(name + "/" if text.endswith("/") else name)


@dataclass(frozen=True)
class Window:
    """A window's occurrence: `key` is `w<id>` for a one-off window, `r<n>@<start>` for a recurring one."""

    key: str
    robots: RobotSelector
    start: float
    end: float
    comment: str
    author: str
    recurring: bool = False
    ended_early: float | None = None  # when a one-off window was ended before its end

    @property
    def until(self) -> float:
        """When the window ends (or ended)."""
        return self.end if self.ended_early is None else min(self.end, self.ended_early)

    def active(self, now: float) -> bool:
        """True while the window holds."""
        return self.start <= now < self.until

    def document(self, now: float) -> dict[str, Any]:
        """The window as GET /api/v1/maintenance shows it."""
        return {
            "id": self.key,
            "robots": self.robots.text,
            "prefix": self.robots.prefix,
            "start": self.start,
            "end": self.until,
            "comment": self.comment,
            "author": self.author,
            "active": self.active(now),
            "recurring": self.recurring,
            "ended_early": self.ended_early is not None and self.ended_early < self.end,
        }


@dataclass(frozen=True)
class RecurringWindow:
    """A window of the configuration that repeats: on `days`, from `begins` to `ends` in `zone`.

    `ends` before (or at) `begins` runs past midnight into the next day, as a night shift does.
    """

    index: int
    robots: RobotSelector
    days: frozenset[int]  # 0 Monday … 6 Sunday: the days an occurrence begins on
    begins: datetime.time
    ends: datetime.time
    zone: ZoneInfo
    comment: str

    def occurrences(self, around: float) -> list[Window]:
        """The occurrences that begin from two days before `around` to two days after, in order."""
        today = datetime.datetime.fromtimestamp(around, self.zone).date()
        found = []
        for offset in range(-2, 3):
            day = today + datetime.timedelta(days=offset)
            if day.weekday() not in self.days:
                continue
            start = datetime.datetime.combine(day, self.begins, self.zone)
            end_day = day if self.ends > self.begins else day + datetime.timedelta(days=1)
            end = datetime.datetime.combine(end_day, self.ends, self.zone)
            begins_at = start.timestamp()
            found.append(
                Window(
                    f"r{self.index}@{int(begins_at)}",
                    self.robots,
                    begins_at,
                    end.timestamp(),
                    self.comment,
                    "configuration",
                    recurring=True,
                )
            )
        return found
