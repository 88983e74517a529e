"""Status messages as a label: the one bounded exception to "messages are never labels".

`ros_diagnostics_status_message{robot, component, hardware_id, level, message} 1` lets an alert rule pull a
component's message into its annotations; `level` (the component's level now, as `ros_diagnostics_level`
has it) lets the rule select only the messages at its alert's level. A label value that changes makes a new
series, so the series exists only for the components chosen by `mode` (by default those whose robot
reports them not OK), and its message is cut to `length` characters.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from overseer.config.metrics import DEFAULT_MESSAGE_LABEL_LENGTH, MESSAGE_LABEL_MODES
from overseer.levels import Level
from overseer.model import Component

ELLIPSIS = "\u2026"

# Lone surrogates cannot be encoded as UTF-8 (a scrape would fail); they become U+FFFD, as the
# codecs turn invalid UTF-8 from the wire.
_SURROGATE = re.compile("[\ud800-\udfff]")


def message_label_value(message: str, length: int) -> str:
    """`message` cut to at most `length` characters, ending in "…" when cut, and valid UTF-8."""
    if len(message) > length:
        message = message[: length - 1] + ELLIPSIS
    return _SURROGATE.sub("\ufffd", message)


@dataclass(frozen=True)
class MessageLabels:
    """Which components get a status-message series (`none`, `problems`, `all`) and how long its label is."""

    mode: str = "problems"
    length: int = DEFAULT_MESSAGE_LABEL_LENGTH

    def __post_init__(self) -> None:
        if self.mode not in MESSAGE_LABEL_MODES:
            raise ValueError(f"message label mode must be one of {MESSAGE_LABEL_MODES}, got {self.mode!r}")
        if self.length < 1:
            raise ValueError(f"message label length must be positive, got {self.length}")

    def wants(self, component: Component) -> bool:
        """Whether `component` has a status-message series."""
        return self.mode == "all" or (self.mode == "problems" and component.level != Level.OK)

    def label(self, component: Component) -> str | None:
        """The message label of `component`'s series, or None when it has no series."""
        return message_label_value(component.message, self.length) if self.wants(component) else None


DEFAULT_MESSAGE_LABELS = MessageLabels()
