"""Payload codecs: wire bytes to and from `DiagnosticArray`."""

from overseer.codec.errors import DecodeError

__all__ = ["DecodeError"]
