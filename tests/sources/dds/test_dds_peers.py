"""DDS peers: configuration, flags, the Cyclone fragment, and peers whose names do not resolve.

The `dds.peers` and `dds.max_participant_index` keys and their flags, the Cyclone fragment they become,
and what happens to a peer whose name does not resolve (Cyclone itself would abort the process).
Discovery across a link without multicast is in test_dds_unicast.py.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from pathlib import Path

import pytest
from cyclonedds.domain import Domain

from overseer.cli import main
from overseer.config import ConfigError, config_from_dict, load_config
from overseer.config.dds import DdsPeer
from overseer.sources.dds.cyclone_config import loopback_only_config, peers_config
from overseer.sources.dds.peers import peer_addresses
from testbed.ports import free_port, fresh_domain_id
from testbed.processes import (
    Exporter,
    overseer_command,
    running_simulator,
    spawn,
    wait_for,
    wait_until_healthy,
)


def test_peers_and_the_probed_index_range_are_read_from_the_file(tmp_path: Path) -> None:
    path = tmp_path / "overseer.yml"
    path.write_text(
        "dds:\n  peers: [10.0.0.5, 'robot7.site-a.example:7410', localhost]\n  max_participant_index: 40\n"
    )
    config = load_config(path)
    assert config.dds.peers == (
        DdsPeer("10.0.0.5"),
        DdsPeer("robot7.site-a.example", 7410),
        DdsPeer("localhost"),
    )
    assert config.dds.max_participant_index == 40
    assert [str(peer) for peer in config.dds.peers] == ["10.0.0.5", "robot7.site-a.example:7410", "localhost"]


def test_by_default_there_are_no_peers_and_indices_up_to_32_are_probed() -> None:
    config = config_from_dict({})
    assert config.dds.peers == ()
    assert config.dds.max_participant_index == 32
    assert config_from_dict({"dds": {"peers": None}}).dds.peers == ()


def test_flags_replace_the_files_peers(tmp_path: Path) -> None:
    path = tmp_path / "overseer.yml"
    path.write_text("dds:\n  peers: [10.0.0.5]\n")
    config = load_config(path, {"dds.peers": ["10.0.0.6", "10.0.0.7:7412"], "dds.max_participant_index": 8})
    assert config.dds.peers == (DdsPeer("10.0.0.6"), DdsPeer("10.0.0.7", 7412))
    assert config.dds.max_participant_index == 8


@pytest.mark.parametrize(
    ("dds", "message"),
    [
        ({"peers": "10.0.0.5"}, "dds.peers: expected a list, got '10.0.0.5'"),
        ({"peers": [5]}, "dds.peers[0]: expected HOST or HOST:PORT, got 5"),
        (
            {"peers": ["10.0.0.5:0"]},
            "dds.peers[0]: expected a port from 1 to 65535 after the host, got '10.0.0.5:0'",
        ),
        (
            {"peers": ["ok", "h:70000"]},
            "dds.peers[1]: expected a port from 1 to 65535 after the host, got 'h:70000'",
        ),
        (
            {"peers": ["host:abc"]},
            "dds.peers[0]: expected a port from 1 to 65535 after the host, got 'host:abc'",
        ),
        ({"peers": ["300.1.1.1"]}, "dds.peers[0]: '300.1.1.1' is not an IPv4 address, in '300.1.1.1'"),
        (
            {"peers": [""]},
            "dds.peers[0]: expected HOST or HOST:PORT with an IPv4 address or a host name, got ''",
        ),
        (
            {"peers": ["-robot.ex"]},
            "dds.peers[0]: expected HOST or HOST:PORT with an IPv4 address or a host name, got '-robot.ex'",
        ),
        (
            {"peers": ["robot 7"]},
            "dds.peers[0]: expected HOST or HOST:PORT with an IPv4 address or a host name, got 'robot 7'",
        ),
        (
            {"peers": ["[::1]:7410"]},
            "dds.peers[0]: expected a port from 1 to 65535 after the host, got '[::1]:7410'",
        ),
        (
            {"peers": ["::1"]},
            "dds.peers[0]: expected a port from 1 to 65535 after the host, got '::1'",
        ),
        (
            {"loopback_only": True, "peers": ["127.bots.ex"]},
            "dds.peers[0]: '127.bots.ex' is not a loopback address, but dds.loopback_only keeps DDS "
            "on loopback",
        ),
        (
            {"loopback_only": True, "peers": ["127.0.0.1", "10.0.0.5"]},
            "dds.peers[1]: '10.0.0.5' is not a loopback address, but dds.loopback_only keeps DDS on loopback",
        ),
        ({"max_participant_index": 0}, "dds.max_participant_index: expected an integer from 1 to 119, got 0"),
        (
            {"max_participant_index": 120},
            "dds.max_participant_index: expected an integer from 1 to 119, got 120",
        ),
        (
            {"max_participant_index": True},
            "dds.max_participant_index: expected an integer from 1 to 119, got True",
        ),
        (
            {"max_participant_index": "8"},
            "dds.max_participant_index: expected an integer from 1 to 119, got '8'",
        ),
        (
            {"domains": [232], "peers": ["10.0.0.5"], "max_participant_index": 63},
            "dds.max_participant_index: 63 needs port 65537 on domain 232, above 65535",
        ),
    ],
)
def test_a_bad_peer_or_index_range_is_a_configuration_error_naming_key_and_value(
    dds: dict[str, object], message: str
) -> None:
    with pytest.raises(ConfigError) as caught:
        config_from_dict({"dds": dds})
    assert str(caught.value) == message


def test_the_highest_index_that_fits_the_ports_of_domain_232_is_accepted() -> None:
    config = config_from_dict({"dds": {"domains": [232], "peers": ["10.0.0.5"], "max_participant_index": 62}})
    assert config.dds.max_participant_index == 62


def test_loopback_peers_go_with_loopback_only() -> None:
    config = config_from_dict({"dds": {"loopback_only": True, "peers": ["127.0.0.1:7410", "localhost"]}})
    assert config.dds.peers == (DdsPeer("127.0.0.1", 7410), DdsPeer("localhost"))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["run", "--dds.peer=10.0.0.5", "--dds.peer=robot:99999"],
            "--dds.peer (dds.peers[1]): expected a port from 1",
        ),
        (
            ["run", "--dds.max-participant-index=0"],
            "--dds.max-participant-index (dds.max_participant_index): expected an integer from 1",
        ),
        (
            ["run", "--dds.loopback-only", "--dds.peer=10.0.0.5"],
            "--dds.peer (dds.peers[0]): '10.0.0.5' is not a loopback",
        ),
        (["simulate", "--dds.peer=robot:0"], "--dds.peer: expected a port from 1 to 65535 after the host"),
        (["simulate", "--dds.loopback-only", "--dds.peer=10.0.0.5"], "--dds.peer: only loopback peers go"),
    ],
)
def test_a_bad_peer_flag_stops_the_command_with_one_line(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    error = capsys.readouterr().err
    assert error.startswith(f"overseer {argv[0]}: configuration error: {message}"), error
    assert error.count("\n") == 1


def test_the_peers_fragment_keeps_every_peer_for_good_and_sets_the_probed_range() -> None:
    fragment = peers_config(["10.0.0.5", "10.0.0.6:7412"], 12)
    discovery = ElementTree.fromstring(fragment).find("Domain/Discovery")
    assert discovery is not None
    assert discovery.findtext("MaxAutoParticipantIndex") == "12"
    assert [peer.attrib for peer in discovery.iterfind("Peers/Peer")] == [
        {"address": "10.0.0.5", "PruneDelay": "inf"},
        {"address": "10.0.0.6:7412", "PruneDelay": "inf"},
    ]
    assert peers_config([], 12) == ""


def test_cyclone_accepts_the_peers_fragment() -> None:
    domain = Domain(fresh_domain_id(), peers_config(["127.0.0.1", "127.0.0.2:7410"], 4))
    assert domain._ref > 0


def test_peer_names_are_resolved_to_ipv4_addresses_once_and_unresolvable_ones_reported() -> None:
    unresolved: list[tuple[DdsPeer, str]] = []
    addresses = peer_addresses(
        [
            DdsPeer("localhost"),
            DdsPeer("no-such-robot.invalid"),
            DdsPeer("127.0.0.1", 7410),
            DdsPeer("127.0.0.1"),
        ],
        lambda peer, error: unresolved.append((peer, error)),
    )
    assert addresses == ["127.0.0.1", "127.0.0.1:7410"]
    assert [peer for peer, _ in unresolved] == [DdsPeer("no-such-robot.invalid")]
    assert unresolved[0][1]


@pytest.mark.servers
def test_an_unresolvable_peer_is_counted_and_the_exporter_hears_its_robots_all_the_same(
    tmp_path: Path, dds_domain: int
) -> None:
    """Cyclone aborts the whole process on a peer name it cannot resolve; the exporter leaves it out.

    The exporter's DDS stays on loopback through an operator's configuration (the loopback-only one as
    XML), since `--dds.loopback-only` itself refuses peers that are not on loopback.
    """
    port = free_port()
    args = [
        *overseer_command(),
        "run",
        f"--web.listen-address=127.0.0.1:{port}",
        f"--dds.domain={dds_domain}",
        f"--dds.cyclonedds-uri={loopback_only_config()}",
        "--dds.peer=no-such-robot.invalid",
        "--dds.peer=127.0.0.1",
    ]
    exporter = Exporter(
        spawn(args, tmp_path / "exporter.log"), tmp_path / "exporter.log", f"http://127.0.0.1:{port}"
    )
    try:
        wait_until_healthy(exporter, 30)
        with running_simulator(tmp_path, dds_domain, "--robots=2", "--rate=4"):
            wait_for(lambda: exporter.robot("robot2") and exporter.robot("robot1"), 30, message="both robots")
            errors = exporter.samples()["overseer_source_errors_total"]
            assert errors[(("reason", "peer_unresolved"), ("transport", "dds"))] == 1
            assert exporter.process.poll() is None
            assert "DDS peer no-such-robot.invalid left out" in exporter.log()
    finally:
        exporter.stop()
