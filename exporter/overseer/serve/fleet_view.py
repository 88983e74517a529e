"""What the HTTP endpoint reads: the fleet's exposition and API documents, from one model or from workers."""

from __future__ import annotations

from typing import Any, Protocol

from overseer.config import Config
from overseer.model import FleetModel
from overseer.serve.api import ComponentQuery, components_document, robot_document, robots_document
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.exposition import FleetExposition
from overseer.serve.exposition_formats import ExpositionFormat
from overseer.serve.message_labels import MessageLabels


class FleetPartUnavailable(RuntimeError):
    """Part of the fleet cannot be read now (an ingest worker is restarting): the endpoint answers 503."""


class FleetView(Protocol):
    """The whole fleet as the endpoint serves it, however many processes hold it."""

    def metrics(self, fmt: ExpositionFormat) -> bytes:
        """The exposition of the whole fleet in `fmt`."""
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

    def __init__(
        self, model: FleetModel, exposition: FleetExposition, assembler: ExpositionAssembler
    ) -> None:
        """Serve `model`, rendering its series with `exposition` and writing them out with `assembler`."""
        self.model = model
        self.exposition = exposition
        self.assembler = assembler

    def metrics(self, fmt: ExpositionFormat) -> bytes:
        """The exposition of the model in `fmt`."""
        return self.assembler.assemble([self.exposition.render_part()], fmt)

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


def model_exposition(model: FleetModel, config: Config) -> FleetExposition:
    """The renderer of `model`'s series the metrics configuration asks for."""
    metrics = config.metrics
    messages = MessageLabels(metrics.message_labels, metrics.message_label_length)
    return FleetExposition(model, metrics.value_key_pattern, messages=messages)
