"""Log lines as text (the default) or as one JSON object a line, for log shippers (`--log.format json`)."""

from __future__ import annotations

import datetime
import json
import logging
from typing import Any

TEXT_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"
# Attributes every LogRecord has; anything else was passed in `extra` and goes into the JSON object.
_STANDARD = set(vars(logging.LogRecord("", 0, "", 0, "", None, None))) | {"message", "asctime", "taskName"}


class JsonFormatter(logging.Formatter):
    """One JSON object a line: time (RFC 3339, UTC), level, logger, message, and any `extra` fields."""

    def format(self, record: logging.LogRecord) -> str:
        """The record as one line of JSON."""
        moment = datetime.datetime.fromtimestamp(record.created, datetime.timezone.utc)
        line: dict[str, Any] = {
            "time": moment.isoformat(timespec="milliseconds").replace("+00:00", "Z"),
            "level": record.levelname.lower(),
            "logger": record.name,
            "message": record.getMessage(),
        }
        for key, value in vars(record).items():
            if key not in _STANDARD and key not in line:
                line[key] = value
        if record.exc_info:
            line["exception"] = self.formatException(record.exc_info)
        return json.dumps(line, ensure_ascii=False, default=str)


def configure_logging(level: str, log_format: str = "text", worker: int | None = None) -> None:
    """Send the whole process's log to stderr at `level`, as `text` or `json` lines.

    In an ingest worker, `worker` is its number: text lines say `[worker N]`, JSON lines carry `worker`.
    """
    handler = logging.StreamHandler()
    if log_format == "json":
        handler.setFormatter(JsonFormatter())
    else:
        label = "" if worker is None else f"[worker {worker}] "
        handler.setFormatter(logging.Formatter(TEXT_FORMAT.replace("%(name)s", label + "%(name)s")))
    if worker is not None:
        handler.addFilter(_WorkerField(worker))
    logging.basicConfig(level=level.upper(), handlers=[handler])


class _WorkerField(logging.Filter):
    """Adds the worker's number to every record (the JSON formatter writes it as a field)."""

    def __init__(self, worker: int) -> None:
        super().__init__()
        self._worker = worker

    def filter(self, record: logging.LogRecord) -> bool:
        record.worker = self._worker
        return True
