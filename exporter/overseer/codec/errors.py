"""The one exception a codec lets escape."""


class DecodeError(ValueError):
    """A payload that is not a well-formed DiagnosticArray."""
