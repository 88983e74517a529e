"""The inventory's labels of each robot as variables of its Icinga 2 host, for apply rules and notifications.

A robot labelled `site: site_a` has `vars.site = "site_a"` on its host, so `assign where host.vars.site ==
"site_a"` and a notification's `users` can follow the inventory. A new host gets them as it is made; a
host whose labels changed (the inventory was reloaded) is updated in place (`POST /v1/objects/hosts/<host>`,
which needs `objects/modify/Host`), a label removed set to null. The names set are kept in
`vars.overseer_labels`, so a restarted exporter knows which variables of a host are labels it set.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from collections.abc import Set as AbstractSet
from typing import Any

from overseer.push.icinga2_client import Icinga2Client, Icinga2Error, error_text, object_path

log = logging.getLogger(__name__)

LABELS_VARIABLE = "overseer_labels"
Labels = tuple[tuple[str, str], ...]


class HostLabels:
    """What each host's label variables should be, what they are, and the updates in between."""

    def __init__(self, client: Icinga2Client) -> None:
        """Update hosts through `client`."""
        self._client = client
        self._wanted: dict[str, Labels] = {}
        self._set: dict[str, Labels] = {}  # as Icinga has them (for the hosts this exporter made)
        self._refused: set[str] = set()  # hosts whose update Icinga refused: not asked again until a change

    def want(self, host: str, labels: Labels) -> None:
        """The labels `host`'s robot has now."""
        if self._wanted.get(host) != labels:
            self._wanted[host] = labels
            self._refused.discard(host)

    def found(self, host: str, variables: Mapping[str, Any]) -> None:
        """A host this exporter made before, as Icinga has it: the label variables it set then."""
        names = variables.get(LABELS_VARIABLE)
        if isinstance(names, list):
            self._set[host] = tuple(
                sorted(
                    (name, str(variables[name]))
                    for name in names
                    if isinstance(name, str) and name in variables
                )
            )

    def variables(self, host: str) -> dict[str, Any]:
        """The label variables of a host about to be made (and taken as set from then on); none without."""
        labels = self._wanted.get(host, ())
        self._set[host] = labels
        return {**dict(labels), LABELS_VARIABLE: [name for name, _ in labels]} if labels else {}

    def current(self, host: str) -> dict[str, Any]:
        """The label variables `host` has in Icinga now, as `variables` gives them (an empty dict without)."""
        labels = self._set.get(host, ())
        return {**dict(labels), LABELS_VARIABLE: [name for name, _ in labels]} if labels else {}

    def forget(self, host: str) -> None:
        """A host deleted: nothing to keep of it."""
        for kept in (self._wanted, self._set):
            kept.pop(host, None)
        self._refused.discard(host)

    def sync(self, created: Mapping[str, AbstractSet[str]]) -> None:
        """Update every host made whose labels changed; Icinga2Error when Icinga cannot be reached.

        An update Icinga refuses (an ApiUser without `objects/modify/Host`) is logged and not asked for
        again until the labels change once more.
        """
        for host, labels in self._wanted.items():
            if host not in created or host in self._refused or self._set.get(host, ()) == labels:
                continue
            attrs: dict[str, Any] = {f"vars.{name}": value for name, value in labels}
            attrs.update(
                {f"vars.{name}": None for name, _ in self._set.get(host, ()) if name not in dict(labels)}
            )
            attrs[f"vars.{LABELS_VARIABLE}"] = [name for name, _ in labels]
            status, document = self._client.request("POST", object_path("hosts", host), {"attrs": attrs})
            if status in (401, 403, 404):
                self._refused.add(host)
                log.warning(
                    "Icinga 2 refused to update the label variables of host %s (HTTP %d: %s); the ApiUser "
                    "needs objects/modify/Host (deploy/icinga2/push/api-user-overseer.conf)",
                    host,
                    status,
                    error_text(document),
                )
                continue
            if not 200 <= status < 300:
                raise Icinga2Error(
                    f"http_{status}", f"updating host {host}: HTTP {status}: {error_text(document)}", status
                )
            self._set[host] = labels
            log.info("Icinga 2 host %s: label variables now %s", host, dict(labels))
