"""Robot and group names as Icinga 2 object names, reversibly.

ROS names hold letters, digits, `_` and `/`. An Icinga object name must not hold `!` (it joins a host
and a service) and `/` would split the REST API's URL path, so a robot's name becomes its host name by
writing `/` as `.` and every other character outside `[A-Za-z0-9_-]` (including `.` and `~` themselves)
as `~XX`, the hex of each of its UTF-8 bytes: `site_a/robot7` → `site_a.robot7`, `robot 1` → `robot~201`.
`robot_name` reverses it; the exact robot name is kept in the host's `vars.ros_robot` as well.
"""

from __future__ import annotations

import re

ROBOT_SERVICE = "ros-diagnostics"
GROUP_SERVICE_PREFIX = "ros-diagnostics-"
_PLAIN = re.compile(r"[A-Za-z0-9_-]")
_ESCAPE = re.compile(r"(?:~[0-9A-F]{2})+")


def object_name(text: str) -> str:
    """`text` as an Icinga 2 object name: `/` as `.`, other unsafe characters as `~XX` per byte."""
    out = []
    for char in text:
        if _PLAIN.fullmatch(char):
            out.append(char)
        elif char == "/":
            out.append(".")
        else:
            out.append("".join(f"~{byte:02X}" for byte in char.encode("utf-8")))
    return "".join(out)


def original_name(name: str) -> str:
    """The text `object_name` made `name` from."""
    unescaped = name.replace(".", "/")
    return _ESCAPE.sub(
        lambda m: bytes.fromhex(m.group().replace("~", "")).decode("utf-8", "replace"), unescaped
    )


def host_name(robot: str) -> str:
    """The Icinga 2 Host of a robot."""
    return object_name(robot)


def robot_name(host: str) -> str:
    """The robot a Host made by `host_name` stands for."""
    return original_name(host)


def group_service_name(group: str) -> str:
    """The Service of one group of a robot's components, e.g. `ros-diagnostics-Power`."""
    return GROUP_SERVICE_PREFIX + object_name(group)


def group_of(component: str) -> str | None:
    """The group of a component: the first segment of an aggregator path (`/Power/Robot Battery` → `Power`).

    Names that are not paths (raw `/diagnostics`, such as `motor_driver: Left`) belong to no group.
    """
    if not component.startswith("/"):
        return None
    first = component[1:].split("/", 1)[0]
    return first or None


def group_pattern(group: str) -> str:
    """The check's `--name-regex` that selects exactly the components of `group`."""
    return f"^/{re.escape(group)}(/|$)"
