"""Registering many robots at once: this exporter's own config package, deployed as one stage.

Icinga 2 walks every object it holds each time `PUT /v1/objects` creates one (to settle which
cluster node is its authority), so one creation costs more the more it holds: 3 ms at 300 hosts,
10 ms at 3,000 on the 2-core test machine, hours for a 10,000-robot fleet one by one. A stage of
a config package is validated and loaded in one reload instead (6,000 objects in 4 s). It takes
the ApiUser permissions `config/query` and `config/modify`, which no filter narrows (whoever holds
them may change any of Icinga's configuration), so it is used only where the ApiUser has them;
otherwise robots are registered one object a call, as before.

A stage replaces the package's whole content, so every deploy holds all the robots registered
this way; a robot forgotten leaves with the next stage, as Icinga refuses to delete such objects
through `DELETE /v1/objects`.
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from overseer.push.icinga2_client import Icinga2Client, Icinga2Error, error_text

log = logging.getLogger(__name__)

POLL_SECONDS = 0.25
CONFIG_FILE = "conf.d/overseer.conf"
# How a request fails while Icinga 2 reloads (its API away for a moment): no failure of Icinga's.
RELOADING_REASONS = frozenset({"connection", "tls", "http_503"})
_UNSAFE_NAME = re.compile(r"[^A-Za-z0-9_-]")
_ERROR_LINE = re.compile(r"critical/config: (.*)")
_T = TypeVar("_T")


class PackageRefused(Exception):
    """The ApiUser may not use config packages (HTTP 401, 403 or 404)."""


class PackageRejected(Exception):
    """Icinga 2 validated a stage and refused it (its reason, from the stage's startup log)."""


def package_name(exporter_id: str) -> str:
    """The package of the exporter marked `exporter_id`: `overseer-<id>`, other characters as `_`."""
    return "overseer-" + _UNSAFE_NAME.sub("_", exporter_id)


def dsl_string(text: str) -> str:
    """`text` as an Icinga 2 DSL string literal; `$` doubled, as Icinga reads every var as a macro string."""
    out = ['"']
    for char in text:
        if char in '"\\':
            out.append("\\" + char)
        elif char == "$":
            out.append("$$")
        elif char == "\n":
            out.append("\\n")
        elif char == "\t":
            out.append("\\t")
        elif ord(char) < 32 or ord(char) == 127:
            out.append(f"\\{ord(char):03o}")
        else:
            out.append(char)
    out.append('"')
    return "".join(out)


def dsl_value(value: object) -> str:
    """A JSON-like value (text, number, bool, null, list) as Icinga 2 DSL."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return dsl_string(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(dsl_value(item) for item in value) + "]"
    raise TypeError(f"no Icinga 2 DSL for {value!r}")


def object_text(kind: str, name: str, attrs: Mapping[str, Any], template: str = "", host: str = "") -> str:
    """One `object Host|Service` definition of the attributes a PUT would send (`vars.x` as `vars["x"]`)."""
    lines = [f"object {kind} {dsl_string(name)} {{"]
    if template:
        lines.append(f"  import {dsl_string(template)}")
    if host:
        lines.append(f"  host_name = {dsl_string(host)}")
    for key, value in attrs.items():
        if key.startswith("vars."):
            lines.append(f"  vars[{dsl_string(key.removeprefix('vars.'))}] = {dsl_value(value)}")
        else:
            lines.append(f"  {key} = {dsl_value(value)}")
    lines.append("}\n")
    return "\n".join(lines)


class ConfigPackage:
    """Deploys stages of one config package and waits until Icinga 2 runs them."""

    def __init__(
        self,
        client: Icinga2Client,
        exporter_id: str,
        timeout: float,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        """Use the package of `exporter_id`; a deploy waits at most `timeout` for Icinga's reload."""
        self.name = package_name(exporter_id)
        self._client = client
        self._timeout = timeout
        self._clock = clock
        self._sleep = sleep
        self._exists = False
        self._stages: list[str] = []  # as the last look at the package found them

    def deploy(self, text: str, loaded: Callable[[], bool]) -> None:
        """Make `text` the package's whole content and wait until Icinga 2, reloaded, runs it.

        `loaded` tells the reloaded Icinga from the one before (a host of `text` is there, or one
        left out is gone). PackageRefused without the permissions, PackageRejected when validation
        fails (Icinga keeps running what it had), Icinga2Error when Icinga cannot be reached or does
        not finish in time.
        """
        deadline = self._clock() + self._timeout
        self._active_stage()  # the package exists from here on
        stage = self._reloading(lambda: self._upload(text))
        while stage is None:  # another update of the package is being loaded (HTTP 423), or a reload
            self._wait(deadline, "taking a stage of")
            stage = self._reloading(lambda: self._upload(text))
        while self._reloading(self._active_stage) != stage:
            status = self._reloading(lambda: self._stage_status(stage))
            if status not in (None, "0"):
                reason = self._rejection(stage)
                self._delete_stage(stage)
                raise PackageRejected(reason)
            self._wait(deadline, f"validating stage {stage} of")
        while not self._reloading(loaded):
            self._wait(deadline, "loading")
        for old in self._stages:
            if old != stage:
                self._delete_stage(old)

    def _upload(self, text: str) -> str | None:
        """Upload a stage: its name, None while Icinga is busy with another update of the package."""
        status, document = self._client.request(
            "POST", f"/v1/config/stages/{self.name}", {"files": {CONFIG_FILE: text}}
        )
        if status == 423:
            return None
        if status in (401, 403):
            raise PackageRefused(f"uploading a stage: HTTP {status}: {error_text(document)}")
        if not 200 <= status < 300:
            raise Icinga2Error(
                f"http_{status}", f"uploading a stage: HTTP {status}: {error_text(document)}", status
            )
        return str(document["results"][0]["stage"])

    def _reloading(self, read: Callable[[], _T]) -> _T | None:
        """What `read` gives, or None while a reload keeps the API away."""
        try:
            return read()
        except Icinga2Error as error:
            if error.reason in RELOADING_REASONS:
                return None
            raise

    def _wait(self, deadline: float, doing: str) -> None:
        if self._clock() >= deadline:
            raise Icinga2Error(
                "timeout", f"Icinga 2 did not finish {doing} package {self.name} in {self._timeout:g}s"
            )
        self._sleep(POLL_SECONDS)

    def _active_stage(self) -> str:
        if not self._exists:
            status, document = self._client.request("POST", f"/v1/config/packages/{self.name}")
            if status in (401, 403, 404):
                raise PackageRefused(f"HTTP {status}: {error_text(document)}")
            self._exists = True  # made now, or it existed (Icinga answers 500 then)
        document = self._call("GET", "/v1/config/packages")
        for package in document["results"]:
            if package.get("name") == self.name:
                self._stages = [str(stage) for stage in package.get("stages") or ()]
                return str(package.get("active-stage") or "")
        self._exists = False
        return ""

    def _stage_status(self, stage: str) -> str | None:
        """The stage's validation exit code ("0": valid), None while it is still being validated."""
        status, payload = self._client.fetch(f"/v1/config/files/{self.name}/{stage}/status")
        if status == 404:
            return None
        if status != 200:
            raise Icinga2Error(
                f"http_{status}", f"reading the status of stage {stage}: HTTP {status}", status
            )
        return payload.decode("utf-8", "replace").strip()

    def _rejection(self, stage: str) -> str:
        status, payload = self._client.fetch(f"/v1/config/files/{self.name}/{stage}/startup.log")
        errors = _ERROR_LINE.findall(payload.decode("utf-8", "replace")) if status == 200 else []
        return "; ".join(errors)[:500] or "validation failed (no reason in its startup log)"

    def _delete_stage(self, stage: str) -> None:
        status, document = self._client.request("DELETE", f"/v1/config/stages/{self.name}/{stage}")
        if not 200 <= status < 300:
            log.info(
                "Icinga 2 kept stage %s of %s: HTTP %d: %s", stage, self.name, status, error_text(document)
            )

    def _call(self, method: str, path: str, body: dict[str, Any] | None = None) -> Any:
        status, document = self._client.request(method, path, body)
        if status in (401, 403):
            raise PackageRefused(f"{method} {path}: HTTP {status}: {error_text(document)}")
        if not 200 <= status < 300:
            raise Icinga2Error(
                f"http_{status}", f"{method} {path}: HTTP {status}: {error_text(document)}", status
            )
        return document
