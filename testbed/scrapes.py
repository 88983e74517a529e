"""What a /metrics scrape shows, read with prometheus-client's parser (which raises on bad text)."""

from __future__ import annotations

from dataclasses import dataclass

from prometheus_client.parser import text_string_to_metric_families


@dataclass(frozen=True)
class Scrape:
    """What one /metrics scrape showed."""

    robots_up: int
    stale_components: int
    components: int
    received: float
    lost: float  # decode errors and drops


def parse_scrape(text: str) -> Scrape:
    """Count the robots up, the components (STALE ones apart) and the messages received and lost."""
    up = stale = components = 0
    received = lost = 0.0
    for family in text_string_to_metric_families(text):
        for sample in family.samples:
            if sample.name == "ros_diagnostics_robot_up":
                up += sample.value == 1
            elif sample.name == "ros_diagnostics_level":
                components += 1
                stale += sample.value == 3
            elif sample.name == "overseer_messages_total":
                if sample.labels["result"] == "received":
                    received += sample.value
                else:
                    lost += sample.value
    return Scrape(up, stale, components, received, lost)
