"""What the HTTP endpoint reads: the fleet's exposition and API documents, from one model or from workers."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Protocol

from prometheus_client.registry import Collector

from overseer.config import Config
from overseer.model import FleetModel
from overseer.serve.api import ComponentQuery, components_document, robot_document, robots_document
from overseer.serve.exposition import FleetExposition
from overseer.serve.message_labels import MessageLabels
from overseer.serve.metrics import FleetCollector


class FleetPartUnavailable(RuntimeError):
    """Part of the fleet cannot be read now (an ingest worker is restarting): the endpoint answers 503."""


class FleetView(Protocol):
    """The whole fleet as the endpoint serves it, however many processes hold it."""

    def metrics_text(self) -> bytes:
        """The Prometheus text exposition of the whole fleet."""
        ...

    def robots_document(self) -> dict[str, Any]:
        """GET /api/v1/robots."""
        ...

    def robot_document(self, name: str) -> dict[str, Any] | None:
        """GET /api/v1/robots/<name>, or None for a robot nobody follows; `FleetPartUnavailable` meanwhile."""
        ...

    def components_document(self, query: ComponentQuery) -> dict[str, Any]:
        """GET /api/v1/components."""
        ...


class ModelView:
    """The fleet held by one model in this process (one ingest worker, the exporter itself)."""

    def __init__(self, model: FleetModel, exposition: FleetExposition) -> None:
        """Serve `model`, rendering its metrics with `exposition`."""
        self.model = model
        self.exposition = exposition

    def metrics_text(self) -> bytes:
        """The exposition of the model."""
        return self.exposition.render()

    def robots_document(self) -> dict[str, Any]:
        """Every robot's summary."""
        return robots_document(self.model.snapshot())

    def robot_document(self, name: str) -> dict[str, Any] | None:
        """One robot with every component, or None."""
        snapshot = self.model.snapshot()
        robot = snapshot.find(name)
        return None if robot is None else robot_document(snapshot, robot)

    def components_document(self, query: ComponentQuery) -> dict[str, Any]:
        """The components matching `query`."""
        return components_document(self.model.snapshot(), query)


def model_renderers(
    model: FleetModel, config: Config, transports: Iterable[str], extra_collectors: Iterable[Collector] = ()
) -> tuple[FleetCollector, FleetExposition]:
    """The two renderings of `model` the metrics config asks for: prometheus-client's, and the fast one."""
    metrics, external_url = config.metrics, config.web.external_url
    messages = MessageLabels(metrics.message_labels, metrics.message_label_length)
    transports = tuple(transports)
    pattern = metrics.value_key_pattern
    collector = FleetCollector(model, pattern, transports, messages=messages, external_url=external_url)
    exposition = FleetExposition(
        model, pattern, transports, extra_collectors, messages=messages, external_url=external_url
    )
    return collector, exposition
