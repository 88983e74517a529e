"""A Zenoh publisher whose token comes after the grace: held, the domain's robot's, then its node's robot's.

The ingest is driven by hand (no session): samples and tokens in the order a slow router would hand them.
"""

from __future__ import annotations

import pytest

from overseer.codec.cdr import encode_diagnostic_array
from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH
from overseer.config.zenoh import ZenohConfig
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources import reattribution
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.topic_names import RAW
from overseer.sources.zenoh import ingest as ingest_module
from overseer.sources.zenoh.ingest import ZenohIngest
from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH, data_key, publisher_gid, publisher_token

KEY = data_key(0, "", RAW)  # diagnostic_updater's absolute /diagnostics
DOMAIN_ROBOT = "domain0"


def token(robot: str, entity: int) -> str:
    """The token of a diagnostic_updater node of `robot` publishing on the absolute /diagnostics."""
    return publisher_token(0, "1f", entity, robot, "driver", RAW, DIAGNOSTIC_ARRAY_HASH, topic_namespace="")


def sample(name: str, number: int, gid: bytes) -> tuple[str, bytes, bytes]:
    """(key, attachment, payload) of a one-status array from publisher `gid`."""
    payload = encode_diagnostic_array(
        DiagnosticArray(0, 0, "", (DiagnosticStatus(1, name, "low", "hw", ()),))
    )
    return KEY, attachment(number, 0, gid), payload


def components(model: FleetModel) -> dict[str, list[str]]:
    """Robot → its component names."""
    return {robot.name: [key[0] for key in robot.components] for robot in model.snapshot().robots}


@pytest.fixture
def no_waiting(monkeypatch: pytest.MonkeyPatch) -> None:
    """No grace before the domain's robot, no second before a moved feed is forgotten."""
    monkeypatch.setattr(ingest_module, "ATTRIBUTION_GRACE_SECONDS", 0.0)
    monkeypatch.setattr(reattribution, "FORGET_AFTER_SECONDS", 0.0)


def ingest_of(model: FleetModel, shard: Shard | None = None) -> ZenohIngest:
    """A Zenoh ingest of `shard` (the whole fleet by default) feeding `model`, with no session."""
    config = ZenohConfig(enabled=True)
    naming = RobotNaming(config.unnamespaced_robot, False, DEFAULT_NAMESPACE_DEPTH)
    return ZenohIngest(config, model, shard or Shard(), naming)


@pytest.mark.usefixtures("no_waiting")
def test_a_late_token_moves_the_publisher_and_forgets_a_domains_robot_that_was_only_it() -> None:
    model = FleetModel()
    ingest = ingest_of(model)
    late = token("robot_z", 10)
    gid = publisher_gid(late)
    ingest.on_sample(*sample("driver: Battery", 1, gid))
    ingest.tick()  # past the grace: the domain's robot's
    assert components(model) == {DOMAIN_ROBOT: ["driver: Battery"]}
    ingest.on_token(late, True)
    ingest.on_sample(*sample("driver: Battery", 2, gid))
    ingest.tick()  # the moved feed forgotten
    assert components(model) == {"robot_z": ["driver: Battery"]}
    assert model.snapshot().forgotten_counts == {"reattributed": 1}


@pytest.mark.usefixtures("no_waiting")
def test_the_domains_robot_keeps_its_other_publishers_and_a_sample_read_before_the_move_goes_nowhere() -> (
    None
):
    model = FleetModel()
    ingest = ingest_of(model)
    late, plain = token("robot_z", 10), b"\x07" * 16  # `plain` never has a token
    ingest.on_sample(*sample("driver: Battery", 1, publisher_gid(late)))
    ingest.on_sample(*sample("Disk", 1, plain))
    ingest.tick()
    assert components(model) == {DOMAIN_ROBOT: ["driver: Battery", "Disk"]}
    ingest.on_token(late, True)
    # A sample that read the domain's robot just before the token, and asks for its ingest after it.
    parsed = ingest._keys[KEY][0]
    assert parsed is not None
    assert ingest._ingest_for(DOMAIN_ROBOT, parsed, publisher_gid(late)) is None
    ingest.tick()
    assert components(model) == {DOMAIN_ROBOT: ["Disk"], "robot_z": []}  # its token made robot_z known
    assert model.snapshot().forgotten_counts == {}


@pytest.mark.usefixtures("no_waiting")
def test_a_publisher_taken_for_another_workers_robot_is_not_remembered() -> None:
    model = FleetModel()
    other = Shard().for_worker(1 - (Shard().worker_of(DOMAIN_ROBOT, 2) or 0), 2)
    ingest = ingest_of(model, other)
    ingest.on_sample(*sample("Disk", 1, b"\x07" * 16))
    ingest.tick()
    assert components(model) == {} and not ingest._by_domain
