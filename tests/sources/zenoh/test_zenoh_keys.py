"""Zenoh key expressions and the `zenoh:` configuration section, without a network."""

from __future__ import annotations

from pathlib import Path

import pytest
import zenoh
from rosbags.typesys import Stores, get_typestore

from overseer.config import ConfigError, load_config
from overseer.config.zenoh import ZenohConfig
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.zenoh.keys import (
    BRIDGE,
    DIAGNOSTIC_ARRAY_HASH,
    DIAGNOSTIC_ARRAY_TYPE,
    RMW_ZENOH,
    DiagnosticsKey,
    RejectedKey,
    attachment_fields,
    attachment_gid,
    bridge_key,
    bridge_liveliness_subscription,
    bridge_publisher_token,
    data_key,
    liveliness_subscription,
    parse_bridge_token,
    parse_data_key,
    parse_publisher,
    parse_publisher_token,
    publisher_gid,
    publisher_token,
)
from overseer.sources.zenoh.session import session_config


def test_the_type_hash_is_diagnostic_arrays_in_jazzy_as_rosbags_computes_it() -> None:
    store = get_typestore(Stores.ROS2_JAZZY)
    assert store.hash_rihs01("diagnostic_msgs/msg/DiagnosticArray") == DIAGNOSTIC_ARRAY_HASH


@pytest.mark.parametrize(
    ("key", "expected"),
    [
        (data_key(0, "robot1", "diagnostics_agg"), ("robot1", "diagnostics_agg", RMW_ZENOH)),
        (data_key(0, "site_a/robot7", "diagnostics"), ("site_a/robot7", "diagnostics", RMW_ZENOH)),
        (data_key(0, "", "diagnostics_agg"), ("", "diagnostics_agg", RMW_ZENOH)),
        (bridge_key("site_a/robot7", "diagnostics_agg"), ("site_a/robot7", "diagnostics_agg", BRIDGE)),
        (bridge_key("", "diagnostics"), ("", "diagnostics", BRIDGE)),
    ],
)
def test_data_keys_of_both_formats_name_the_robot_by_its_namespace(
    key: str, expected: tuple[str, str, str]
) -> None:
    parsed = parse_data_key(key, 0)
    assert (parsed.namespace, parsed.kind, parsed.key_format) == expected


def test_another_type_hash_is_still_a_diagnostics_key() -> None:
    parsed = parse_data_key(data_key(3, "r", "diagnostics_agg", "RIHS01_00"), 3)
    assert parsed == DiagnosticsKey("r", "diagnostics_agg", RMW_ZENOH, "RIHS01_00")


@pytest.mark.parametrize(
    ("key", "reason"),
    [
        (f"0/r/diagnostics_agg/std_msgs::msg::dds_::String_/{DIAGNOSTIC_ARRAY_HASH}", "unexpected_type"),
        (data_key(1, "r", "diagnostics_agg"), "unrecognised_key"),  # another domain
        (f"0/r/diagnostics_agg/{DIAGNOSTIC_ARRAY_TYPE}", "unrecognised_key"),  # no hash
        (data_key(0, "9lives", "diagnostics_agg"), "invalid_namespace"),
        (data_key(0, "we ird", "diagnostics_agg"), "invalid_namespace"),
        ("ro\u2603bot/diagnostics_agg", "invalid_namespace"),
        ("0/robot1/diagnostics_agg", "invalid_namespace"),  # a domain where a namespace goes
    ],
)
def test_keys_that_are_not_a_robots_diagnostics_are_rejected_with_a_reason(key: str, reason: str) -> None:
    with pytest.raises(RejectedKey, match=reason):
        parse_data_key(key, 0)


def test_publisher_tokens_name_the_robot_and_other_tokens_are_ignored() -> None:
    token = publisher_token(
        0, "abc", 12, "site_a/robot7", "aggregator", "diagnostics_agg", DIAGNOSTIC_ARRAY_HASH
    )
    assert parse_publisher_token(token, 0) == DiagnosticsKey(
        "site_a/robot7", "diagnostics_agg", RMW_ZENOH, DIAGNOSTIC_ARRAY_HASH
    )
    assert parse_publisher_token(token, 1) is None
    assert parse_publisher_token(token.replace("/MP/", "/MS/"), 0) is None  # a subscription
    assert (
        parse_publisher_token(token.replace(DIAGNOSTIC_ARRAY_TYPE, "std_msgs::msg::dds_::String_"), 0) is None
    )
    assert parse_publisher_token(token.replace("%diagnostics_agg", "%diagnostics_aggx"), 0) is None
    assert parse_publisher_token(token.replace("%site_a", "%9site"), 0) is None
    assert parse_publisher_token(token + "/extra", 0) is None
    unnamespaced = publisher_token(0, "abc", 1, "", "agg", "diagnostics", DIAGNOSTIC_ARRAY_HASH)
    assert parse_publisher_token(unnamespaced, 0) == DiagnosticsKey(
        "", "diagnostics", RMW_ZENOH, DIAGNOSTIC_ARRAY_HASH
    )


def test_the_token_subscriptions_match_every_diagnostics_publishers_token_and_no_other_type() -> None:
    # Matched by Zenoh itself: the subscriptions name the type, with no wildcard inside a chunk.
    def matched(subscription: str, token: str) -> bool:
        return bool(zenoh.KeyExpr(subscription).intersects(zenoh.KeyExpr(token)))

    rmw = liveliness_subscription(0)
    tokens = [
        publisher_token(
            0, "abc", 12, "site_a/robot7", "aggregator", "diagnostics_agg", DIAGNOSTIC_ARRAY_HASH
        ),
        publisher_token(
            0, "abc", 3, "robot_b", "driver", "diagnostics", DIAGNOSTIC_ARRAY_HASH, topic_namespace=""
        ),
        publisher_token(0, "abc", 4, "", "agg", "diagnostics", "RIHS01_" + "0" * 64),  # another revision
    ]
    assert all(matched(rmw, token) for token in tokens)
    string_topic = tokens[0].replace(DIAGNOSTIC_ARRAY_TYPE, "std_msgs::msg::dds_::String_")
    assert not matched(rmw, string_topic)
    assert not matched(rmw, tokens[0].replace("/MP/", "/MS/"))  # a subscription
    assert not matched(liveliness_subscription(1), tokens[0])
    bridge = bridge_liveliness_subscription()
    assert matched(bridge, bridge_publisher_token("f00d", "site_a/robot7", "diagnostics_agg"))
    assert matched(bridge, bridge_publisher_token("f00d", "", "diagnostics"))
    assert not matched(
        bridge, bridge_publisher_token("f00d", "r", "diagnostics").replace("DiagnosticArray", "String")
    )


def test_bridge_tokens_name_the_robot_and_other_tokens_are_ignored() -> None:
    token = bridge_publisher_token("f00d", "site_a/robot7", "diagnostics_agg")
    assert (
        token
        == "@/f00d/@ros2_lv/MP/site_a§robot7§diagnostics_agg/diagnostic_msgs§msg§DiagnosticArray/:1:0:0,10"
    )
    assert parse_bridge_token(token) == DiagnosticsKey("site_a/robot7", "diagnostics_agg", BRIDGE, "")
    assert parse_bridge_token(bridge_publisher_token("f00d", "", "diagnostics")) == DiagnosticsKey(
        "", "diagnostics", BRIDGE, ""
    )
    assert parse_bridge_token(token.replace("DiagnosticArray", "String")) is None
    assert parse_bridge_token(token.replace("/MP/", "/MS/")) is None
    assert parse_bridge_token(token.replace("site_a§", "9§")) is None
    assert parse_bridge_token(token + "/x") is None


def test_zenoh_section_turns_the_transport_on_with_its_keys(tmp_path: Path) -> None:
    native = tmp_path / "zenoh.json5"
    native.write_text('{mode: "peer", transport: {link: {tx: {lease: 5000}}}}')
    file = tmp_path / "overseer.yml"
    file.write_text(
        "zenoh:\n  connect: [tcp/router.example:7447]\n  domain: 7\n"
        f"  config: {native}\n  key_formats: [bridge]\n  robot_name: solo\n"
    )
    config = load_config(file).zenoh
    assert config == ZenohConfig(
        True, None, ("tcp/router.example:7447",), (), 7, str(native), ("bridge",), "solo"
    )
    assert not load_config(None).zenoh.enabled
    assert load_config(None, {"zenoh.listen": ["tcp/0.0.0.0:7447"]}).zenoh.enabled
    assert not load_config(None, {"zenoh.enabled": False, "zenoh.domain": 1}).zenoh.enabled
    assert not load_config(None, {"dds.enabled": False}).dds.enabled
    native_config = session_config(config)
    assert native_config.get_json("mode") == '"peer"'  # the native file's, since none was given
    assert native_config.get_json("connect/endpoints") == '["tcp/router.example:7447"]'
    assert session_config(ZenohConfig(True)).get_json("scouting/multicast/enabled") == "false"


def test_shared_memory_is_off_unless_asked_for_even_under_a_native_file_that_turns_it_on(
    tmp_path: Path,
) -> None:
    native = tmp_path / "zenoh.json5"
    native.write_text("{transport: {shared_memory: {enabled: true}}}")
    key = "transport/shared_memory/enabled"
    assert session_config(ZenohConfig(True)).get_json(key) == "false"
    assert session_config(load_config(None, {"zenoh.config": str(native)}).zenoh).get_json(key) == "false"
    asked = load_config(None, {"zenoh.config": str(native), "zenoh.shared_memory": True}).zenoh
    assert asked.shared_memory and session_config(asked).get_json(key) == "true"


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"zenoh.mode": "router"}, "zenoh.mode: expected client or peer, got 'router'"),
        ({"zenoh.connect": ["robot1:7447"]}, "zenoh.connect: expected an endpoint such as tcp/host:7447"),
        ({"zenoh.listen": [7447]}, "zenoh.listen: expected a non-empty string, got 7447"),
        ({"zenoh.domain": 300}, "zenoh.domain: expected a ROS domain id from 0 to 232, got 300"),
        ({"zenoh.domain": "0"}, "zenoh.domain: expected a ROS domain id from 0 to 232, got '0'"),
        ({"zenoh.key_formats": ["dds"]}, "zenoh.key_formats: expected rmw_zenoh or bridge, got 'dds'"),
        ({"zenoh.key_formats": []}, "zenoh.key_formats: expected at least one"),
        ({"zenoh.config": "/nonexistent/z.json5"}, "zenoh.config: cannot read '/nonexistent/z.json5'"),
        ({"zenoh.enabled": "yes"}, "zenoh.enabled: expected true or false, got 'yes'"),
        ({"zenoh.shared_memory": "on"}, "zenoh.shared_memory: expected true or false, got 'on'"),
        ({"zenoh.routers": []}, "zenoh.routers: unknown key"),
    ],
)
def test_bad_zenoh_settings_are_refused_naming_the_key(overrides: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace("[", r"\[")):
        load_config(None, overrides)


def test_a_native_file_zenoh_cannot_read_is_refused_naming_the_key(tmp_path: Path) -> None:
    native = tmp_path / "bad.json5"
    native.write_text("{mode: ")
    with pytest.raises(ConfigError, match=r"zenoh\.config: .* is not a usable Zenoh configuration"):
        session_config(load_config(None, {"zenoh.config": str(native)}).zenoh)


def test_a_publisher_token_names_its_node_and_its_gid_is_the_tokens_hash() -> None:
    token = publisher_token(0, "a1b2", 7, "robot_a/drivers", "lidar", "diagnostics", DIAGNOSTIC_ARRAY_HASH)
    publisher = parse_publisher(token, 0)
    assert publisher is not None
    assert (publisher.node_namespace, publisher.node_name) == ("/robot_a/drivers", "lidar")
    assert publisher.topic.namespace == "robot_a/drivers" and publisher.topic.kind == "diagnostics"
    # rmw_zenoh: memcpy of XXH3-128's low then high 64 bits, on a little-endian host
    assert publisher.gid == publisher_gid(token) and len(publisher.gid) == 16
    assert publisher.gid != publisher_gid(token.replace("lidar", "camera"))
    assert parse_publisher(token, 1) is None


@pytest.mark.parametrize(
    ("raw", "expected"),
    [
        (attachment(1, 1_700_000_000_000_000_000, bytes(range(16))), bytes(range(16))),  # Jazzy: 33 bytes
        (  # an earlier rmw_zenoh named its fields
            b"\x0fsequence_number"
            + bytes(8)
            + b"\x10source_timestamp"
            + bytes(8)
            + b"\x0asource_gid\x10"
            + bytes(range(16)),
            bytes(range(16)),
        ),
        (None, None),
        (b"", None),
        (bytes(33), None),  # no GID length where it belongs
        (b"\x0asource_gid" + bytes(5), None),
    ],
)
def test_the_attachment_gives_its_publishers_gid(raw: bytes | None, expected: bytes | None) -> None:
    assert attachment_gid(raw) == expected


@pytest.mark.parametrize(
    ("raw", "expected"),
    [
        (attachment(41, 1_700_000_000_000_000_000, bytes(range(16))), 41),  # Jazzy: 33 bytes
        (attachment(2**40 + 3, 0, bytes(range(16))), 2**40 + 3),
        (  # an earlier rmw_zenoh named its fields
            b"\x0fsequence_number"
            + (7).to_bytes(8, "little")
            + b"\x10source_timestamp"
            + bytes(8)
            + b"\x0asource_gid\x10"
            + bytes(range(16)),
            7,
        ),
        (None, None),
        (b"", None),
        (bytes(33), None),  # not rmw_zenoh's: no GID length where it belongs
        (b"\x0fsequence_number\x01\x02\x0asource_gid" + bytes(16), None),  # the number cut short
        (b"\x0asource_gid" + bytes(16), None),  # a GID and no number
    ],
)
def test_the_attachment_gives_its_samples_sequence_number(raw: bytes | None, expected: int | None) -> None:
    assert attachment_fields(raw)[1] == expected


@pytest.mark.parametrize(
    ("raw", "expected"),
    [
        (attachment(41, 5, bytes(range(16))), (bytes(range(16)), 41)),
        (b"\x0asource_gid" + bytes(range(16)), (bytes(range(16)), None)),  # a GID and no number
        (bytes(33), (None, None)),
        (None, (None, None)),
    ],
)
def test_one_reading_of_the_attachment_gives_its_gid_and_number_together(
    raw: bytes | None, expected: tuple[bytes | None, int | None]
) -> None:
    assert attachment_fields(raw) == expected
