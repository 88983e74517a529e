"""The Nagios verdict on one robot, as data: its state, its summary, its per-level lists, its perfdata.

`judge` decides; `plugin_output` writes what a Nagios plugin prints (the check's stdout), and the Icinga 2
push hands the same verdict's parts to Icinga as they are, so every path says the same thing. Only the
standard library's cheapest modules are used here: `check_ros_diagnostics` starts once per check, and its
start-up time is most of its run time.
"""

from __future__ import annotations

import time  # built into the interpreter: no start-up cost

from overseer.severity import SEVERITY_RANK

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing (14 ms)
if TYPE_CHECKING:
    import re


OK, WARNING, CRITICAL, UNKNOWN = 0, 1, 2, 3
STATE_NAMES = ("OK", "WARNING", "CRITICAL", "UNKNOWN")
STALE_LEVEL = 3

_COUNT_LABELS = (("error", 2), ("warn", 1), ("stale", 3), ("ok", 0))
_SUMMARY_COMPONENTS = 3
_SUMMARY_MESSAGE_CHARS = 60
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"  # compiled on first use, by re's cache


class ReportedComponent:
    """One diagnostic component as the exporter's JSON API reports it."""

    __slots__ = ("hardware_id", "level", "message", "name", "values")

    def __init__(
        self, name: str, hardware_id: str, level: int, message: str, values: list[tuple[str, str]]
    ) -> None:
        """Keep the fields; `level` is the effective one (3 when stale)."""
        self.name = name
        self.hardware_id = hardware_id
        self.level = level
        self.message = message
        self.values = values


class Maintenance:
    """The maintenance window a robot is in: which, until when (unix time), who opened it and why."""

    __slots__ = ("author", "comment", "until", "window")

    def __init__(self, window: str, until: float, author: str, comment: str) -> None:
        """Keep the fields."""
        self.window = window
        self.until = until
        self.author = author
        self.comment = comment


class ReportedRobot:
    """One robot as the exporter's JSON API reports it."""

    __slots__ = (
        "components",
        "generated_at",
        "last_message",
        "listed",
        "maintenance",
        "name",
        "publisher_alive",
        "up",
    )

    def __init__(
        self,
        name: str,
        up: bool,
        last_message: float | None,
        generated_at: float,
        components: list[ReportedComponent],
        publisher_alive: bool = True,
        maintenance: Maintenance | None = None,
        listed: bool = False,
    ) -> None:
        """Keep the fields; times are the exporter's unix times; `listed` in the exporter's inventory."""
        self.listed = listed
        self.publisher_alive = publisher_alive
        self.maintenance = maintenance
        self.name = name
        self.up = up
        self.last_message = last_message
        self.generated_at = generated_at
        self.components = components


class Settings:
    """How to judge and what to print, from the command line."""

    __slots__ = ("name", "name_regex", "perfdata_values", "stale_state", "verbosity")

    def __init__(
        self,
        name: str = "",
        name_regex: re.Pattern[str] | None = None,
        stale_state: int = UNKNOWN,
        perfdata_values: bool = False,
        verbosity: int = 0,
    ) -> None:
        """Keep the fields; an empty `name` keeps every component."""
        self.name = name
        self.name_regex = name_regex
        self.stale_state = stale_state
        self.perfdata_values = perfdata_values
        self.verbosity = verbosity


def worst_state(states: list[int]) -> int:
    """The most severe Nagios state by CRITICAL > WARNING > UNKNOWN > OK; OK when empty."""
    return max(states, key=SEVERITY_RANK.__getitem__, default=OK)


def state_of(component: ReportedComponent, stale_state: int) -> int:
    """The Nagios state of a component: its level, or `stale_state` when it is stale."""
    return stale_state if component.level == STALE_LEVEL else component.level


def select(components: list[ReportedComponent], settings: Settings) -> list[ReportedComponent]:
    """The components whose name contains `settings.name` (any case) and matches `settings.name_regex`."""
    needle = settings.name.casefold()
    pattern = settings.name_regex
    return [
        component
        for component in components
        if needle in component.name.casefold() and (pattern is None or pattern.search(component.name))
    ]


class Verdict:
    """What the check finds of one robot: a Nagios state, one line saying why, the components by section.

    `summary` is the status line after `STATE - `; `sections` hold the paper's sensor lists in order
    (CRITICAL, WARNING, stale, OK), each a title and its components, only those with any; `perfdata`
    the performance data items.
    """

    __slots__ = ("perfdata", "sections", "state", "summary")

    def __init__(
        self,
        state: int,
        summary: str,
        sections: list[tuple[str, list[ReportedComponent]]],
        perfdata: list[str],
    ) -> None:
        """Keep the fields."""
        self.state = state
        self.summary = summary
        self.sections = sections
        self.perfdata = perfdata

    @property
    def status_text(self) -> str:
        """The status line without its performance data: `CRITICAL - robot3: ...`."""
        return f"{STATE_NAMES[self.state]} - {self.summary}"

    def long_output(self, verbosity: int = 0) -> list[str]:
        """The lines after the status line: each section's title, then its components."""
        lines = []
        for title, members in self.sections:
            lines.append(title)
            lines.extend(component_line(component, verbosity) for component in members)
        return lines


def judge(robot: ReportedRobot, settings: Settings) -> Verdict:
    """The verdict on `robot`: its components chosen by `settings` and judged the Nagios way.

    A robot in maintenance is judged the same; the summary says until when and why (Icinga's downtime,
    not the state, keeps the notifications quiet).
    """
    verdict = judge_state(robot, settings)
    if robot.maintenance is not None:
        verdict.summary += maintenance_text(robot.maintenance)
    return verdict


def judge_state(robot: ReportedRobot, settings: Settings) -> Verdict:
    """`judge` without the maintenance window."""
    name = clean(robot.name)
    if not robot.up:
        return Verdict(settings.stale_state, f"{name} is down: {down_text(robot)}", [], [])
    components = sorted(select(robot.components, settings), key=lambda c: (c.name, c.hardware_id))
    if not components:
        return Verdict(UNKNOWN, f"{name}: {clean(no_match_text(robot, settings))}", [], [])
    states = [state_of(component, settings.stale_state) for component in components]
    state = worst_state(states)
    return Verdict(
        state,
        f"{name}: {summary(components, states, state)}",
        sections(components, states, settings.stale_state),
        perfdata(components, settings.perfdata_values),
    )


def plugin_output(verdict: Verdict, verbosity: int = 0) -> str:
    """What a Nagios plugin prints: the status line with its perfdata after ` | `, then the long output."""
    first_line = verdict.status_text
    if verdict.perfdata:
        first_line += " | " + " ".join(verdict.perfdata)
    return "\n".join([first_line, *verdict.long_output(verbosity)])


def maintenance_text(maintenance: Maintenance) -> str:
    """What the status line adds for a robot in maintenance: until when, who and why."""
    until = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(maintenance.until))
    comment = clean(maintenance.comment)
    if len(comment) > _SUMMARY_MESSAGE_CHARS:
        comment = comment[: _SUMMARY_MESSAGE_CHARS - 3].rstrip() + "..."
    return f" [in maintenance until {until}, {clean(maintenance.author)}: {comment}]"


def down_text(robot: ReportedRobot) -> str:
    """Why a robot is down: its publisher left, silent for how long, or never heard from."""
    if robot.last_message is None:
        if robot.listed:
            return "listed in the inventory, never heard"
        return "the exporter knows it but never received its diagnostics"
    if not robot.publisher_alive:
        return "its diagnostics publisher left (the middleware said so)"
    silent_seconds = max(0, round(robot.generated_at - robot.last_message))
    return f"no diagnostics received for {silent_seconds} s"


def no_match_text(robot: ReportedRobot, settings: Settings) -> str:
    """Why no component is left to judge."""
    if not robot.components:
        return "the robot reports no components"
    wanted = []
    if settings.name:
        wanted.append(f"name containing {settings.name!r}")
    if settings.name_regex is not None:
        wanted.append(f"name matching /{settings.name_regex.pattern}/")
    return f"no component with {' and '.join(wanted)} among its {len(robot.components)} components"


def summary(components: list[ReportedComponent], states: list[int], state: int) -> str:
    """The status line's text: the components in the worst state with their messages, or all is well."""
    if state == OK:
        return f"{len(components)} component{'s' if len(components) != 1 else ''} OK"
    worst = leaves_first([c for c, s in zip(components, states, strict=True) if s == state])
    named = ", ".join(f"{clean(c.name)} ({short_message(c)})" for c in worst[:_SUMMARY_COMPONENTS])
    more = len(worst) - _SUMMARY_COMPONENTS
    others = [
        f"{count} {STATE_NAMES[other]}"
        for other in (CRITICAL, WARNING, UNKNOWN)
        if other != state and (count := states.count(other))
    ]
    return (
        named + (f" and {more} more" if more > 0 else "") + (f" (also {', '.join(others)})" if others else "")
    )


def leaves_first(components: list[ReportedComponent]) -> list[ReportedComponent]:
    """`components` with group statuses (names that prefix another's) after the leaves they summarise."""
    names = [component.name for component in components]

    def is_group(component: ReportedComponent) -> bool:
        prefix = component.name.rstrip("/") + "/"
        return any(name.startswith(prefix) for name in names)

    return sorted(components, key=is_group)


def short_message(component: ReportedComponent) -> str:
    """A component's message cut for the status line; stale ones say so."""
    message = clean(component.message)
    if component.level == STALE_LEVEL:
        message = f"stale: {message}" if message else "stale"
    if len(message) > _SUMMARY_MESSAGE_CHARS:
        message = message[: _SUMMARY_MESSAGE_CHARS - 3].rstrip() + "..."
    return message or "no message"


def sections(
    components: list[ReportedComponent], states: list[int], stale_state: int
) -> list[tuple[str, list[ReportedComponent]]]:
    """The paper's sensor lists (CRITICAL, WARNING, stale, OK), each with its components; no empty one."""
    titles = (
        "CRITICAL sensor(s) list:",
        "WARNING sensor(s) list:",
        f"{STATE_NAMES[stale_state]} (stale) sensor(s) list:",
        "OK sensor(s) list:",
    )
    members: list[list[ReportedComponent]] = [[] for _ in titles]
    for component, state in zip(components, states, strict=True):
        members[section_of(component, state)].append(component)
    return [(title, listed) for title, listed in zip(titles, members, strict=True) if listed]


def section_of(component: ReportedComponent, state: int) -> int:
    """The long-output section of a component: 0 CRITICAL, 1 WARNING, 2 stale (whatever its state), 3 OK."""
    return 2 if component.level == STALE_LEVEL else (3, 1, 0)[state]


def component_line(component: ReportedComponent, verbosity: int) -> str:
    """One long-output line: name, hardware id when set, message, and key-values when verbose."""
    line = clean(component.name)
    if component.hardware_id:
        line += f" [{clean(component.hardware_id)}]"
    line += f": {clean(component.message)}"
    if verbosity > 0 and component.values:
        line += " (" + ", ".join(f"{clean(key)}={clean(value)}" for key, value in component.values) + ")"
    return line


def clean(text: str) -> str:
    """`text` on one line and without `|`, which would start the performance data."""
    return " ".join(text.replace("|", "¦").split())


def perfdata(components: list[ReportedComponent], with_values: bool) -> list[str]:
    """Counts per level, then (when asked) every numeric key-value, as Nagios perfdata items."""
    levels = [component.level for component in components]
    items = [f"'{label}'={levels.count(level)};;;0" for label, level in _COUNT_LABELS]
    if with_values:
        items.extend(value_perfdata(components))
    return items


def value_perfdata(components: list[ReportedComponent]) -> list[str]:
    """`'<component>:<key>'=<number>;;;;` for every key-value that is a finite number."""
    items = []
    for component in components:
        prefix = component.name + (f"[{component.hardware_id}]" if component.hardware_id else "")
        for key, text in component.values:
            number = parse_number(text)
            if number is not None:
                items.append(f"{perf_label(prefix + ':' + key)}={perf_number(number)};;;;")
    return items


def parse_number(text: str) -> float | None:
    """The finite number `text` spells in plain decimal or exponent notation, else None (NaN too)."""
    import re  # only --perfdata-values pays for it

    text = text.strip()
    if not re.fullmatch(_NUMBER, text):
        return None
    number = float(text)
    return number if abs(number) != float("inf") else None


def perf_number(number: float) -> str:
    """`number` in plain decimal notation, as the perfdata grammar ([-0-9.]) wants: no exponent."""
    text = repr(number)
    if "e" not in text:
        return text.removesuffix(".0")
    mantissa, exponent = text.split("e")
    decimals = len(mantissa.partition(".")[2]) - int(exponent)
    return f"{number:.{max(decimals, 0)}f}"


def perf_label(label: str) -> str:
    """A quoted perfdata label: quotes doubled, `=` and `|` (which end a label) replaced."""
    return "'" + clean(label).replace("'", "''").replace("=", "_") + "'"
