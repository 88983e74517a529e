"""Transports: each subscribes to robots' diagnostics and hands them to the fleet model."""

from typing import Protocol


class Source(Protocol):
    """A transport feeding the fleet model; `start` must not block, `stop` releases everything."""

    transport: str

    def start(self) -> None:
        """Begin receiving diagnostics in background threads."""

    def stop(self) -> None:
        """Stop receiving and release connections."""
