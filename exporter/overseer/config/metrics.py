"""The `metrics:` section: which key-values are exported, and which components carry their message."""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.options import Option, option
from overseer.config.parsers import boolean, listed, string, whole_number

MESSAGE_LABEL_MODES = ("none", "problems", "all")
DEFAULT_MESSAGE_LABEL_LENGTH = 100
OPTIONS: tuple[Option, ...] = (
    option(
        "metrics.value_keys",
        ".*",
        "a regular expression (full match) of the key-value keys exported as numbers; repeat for several; "
        "`[]` (on the command line `'(?!)'`) exports none",
        kind="repeated",
        metavar="REGEX",
        flag="--metrics.value-key",
    ),
    option(
        "metrics.message_labels",
        "problems",
        "which components get ros_diagnostics_status_message: none, problems (reported not OK), all",
        metavar="MODE",
    ),
    option(
        "metrics.message_label_length",
        str(DEFAULT_MESSAGE_LABEL_LENGTH),
        "characters of the status-message label (1-1024), … included when cut",
        metavar="N",
    ),
    option(
        "metrics.level_changes",
        "true",
        "export ros_diagnostics_level_changes_total, a series per component (true or false)",
        metavar="BOOL",
    ),
    option(
        "metrics.render_ahead",
        "true",
        "render what changed shortly before each scrape a steady scraper is expected to make (true or false)",
        metavar="BOOL",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}


NO_VALUE_KEYS = "(?!)"  # the pattern of `value_keys: []`, which no key matches: no value is exported


@dataclass(frozen=True)
class MetricsConfig:
    """What the /metrics view exports beyond levels."""

    value_keys: tuple[str, ...] = (".*",)
    # Which components get ros_diagnostics_status_message (none, problems, all), and how many characters
    # its message label keeps, "…" included when cut.
    message_labels: str = "problems"
    message_label_length: int = DEFAULT_MESSAGE_LABEL_LENGTH
    # ros_diagnostics_level_changes_total, a series per component (flapping); off saves that many.
    level_changes: bool = True
    # Render what changed shortly before the scrape a steady scraper is expected to make (render_ahead).
    render_ahead: bool = True

    @property
    def value_key_pattern(self) -> re.Pattern[str]:
        """One compiled pattern matching every allowed key-value key in full."""
        # `NO_VALUE_KEYS` given as a key (`--metrics.value-key='(?!)'`, the command line's "none") stays
        # itself, so that the exposition knows no value is exported.
        keys = [f"(?:{p})" for p in self.value_keys if p != NO_VALUE_KEYS]
        return re.compile("|".join(keys) or NO_VALUE_KEYS)


def metrics_config(raw: dict[str, Any]) -> MetricsConfig:
    """The section from its mapping."""
    config = MetricsConfig()
    if "message_labels" in raw:
        mode = raw["message_labels"]
        if mode not in MESSAGE_LABEL_MODES:
            raise ConfigError(
                f"metrics.message_labels: expected one of {', '.join(MESSAGE_LABEL_MODES)}, got {mode!r}"
            )
        config = replace(config, message_labels=mode)
    if "message_label_length" in raw:
        length = whole_number(raw["message_label_length"], "metrics.message_label_length", 1, 1024)
        config = replace(config, message_label_length=length)
    if "level_changes" in raw:
        config = replace(config, level_changes=boolean(raw["level_changes"], "metrics.level_changes"))
    if "render_ahead" in raw:
        config = replace(config, render_ahead=boolean(raw["render_ahead"], "metrics.render_ahead"))
    if "value_keys" in raw:
        patterns = tuple(
            string(p, "metrics.value_keys") for p in listed(raw["value_keys"], "metrics.value_keys")
        )
        for pattern in patterns:
            try:
                re.compile(pattern)
            except re.error as error:
                raise ConfigError(
                    f"metrics.value_keys: {pattern!r} is not a regular expression: {error}"
                ) from None
        config = replace(config, value_keys=patterns)
    return config
