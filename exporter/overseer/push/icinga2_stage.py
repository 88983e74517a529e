"""A config package stage deployed beside the push, in a thread of its own.

Icinga 2 validates and loads a stage for a minute or more at 10,000 robots (each stage holds every robot
the package registered). Deployed by the push's own thread, it held back every registered robot's results
for that long, past their TTL; beside it, only the robots whose objects a stage registers wait for it.
(A stage that deletes forgotten robots is still deployed by the push's thread: `Icinga2Objects._unpackage`.)
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from overseer.push.icinga2_client import Icinga2Error
from overseer.push.icinga2_package import PackageRefused, PackageRejected

log = logging.getLogger(__name__)


class StageInFlight:
    """One stage being deployed: the hosts and services it registers, and how its deploy ended."""

    def __init__(
        self, staged: dict[str, frozenset[str]], hosts: int, services: int, deploy: Callable[[], None]
    ) -> None:
        """Start `deploy` in a daemon thread; `staged` (host → services) are what it registers."""
        self.staged = staged
        self.hosts = hosts  # how many of `staged`'s hosts are new
        self.services = services  # how many services it adds, to new hosts and to those of the package
        self._error: Exception | None = None
        self._thread = threading.Thread(target=self._run, args=(deploy,), name="icinga2-stage", daemon=True)
        self._thread.start()

    def _run(self, deploy: Callable[[], None]) -> None:
        try:
            deploy()
        except Icinga2Error as error:
            # A copy, with neither traceback nor context: their frames hold the stage's text (30 MB at
            # 10,000 robots) until the push takes the outcome into account.
            self._error = Icinga2Error(error.reason, str(error), error.status)
        except (PackageRefused, PackageRejected) as error:
            self._error = type(error)(str(error))
        except Exception as error:  # handed to the push as a failure of its own, never lost in a thread
            log.exception("Icinga 2 push: deploying a stage failed unexpectedly")
            self._error = Icinga2Error("stage", f"deploying a stage failed: {error!r}")

    @property
    def done(self) -> bool:
        """Whether the deploy ended, well or not."""
        return not self._thread.is_alive()

    def join(self, timeout: float) -> None:
        """Wait at most `timeout` for the deploy to end."""
        self._thread.join(timeout)

    def raise_failure(self) -> None:
        """Raise what ended the deploy, if anything did (only once `done`)."""
        error, self._error = self._error, None
        if error is not None:
            try:
                raise error
            finally:
                del error  # or the frame its traceback holds would hold it: a cycle (see Icinga2Client)
