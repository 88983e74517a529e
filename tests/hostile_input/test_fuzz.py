"""Property-based fuzzing of everything that reads untrusted or hand-written input.

- Both DiagnosticArray decoders (ROS 2 CDR, ROS 1) and the TCPROS connection header: random bytes and
  mutations of valid payloads (bit flips, cuts, splices, lying lengths) raise only the codec's own error.
- The views: a fleet model fed hostile arrays (quotes, backslashes, newlines, NUL, invalid UTF-8, NaN and
  infinities in key-values, out-of-range levels, caps) renders an exposition that prometheus-client's
  parsers and `promtool check metrics` accept, whose labels read back as exactly the model's names, and
  which is byte-identical to prometheus-client's rendering of the collector.
- The configuration and the web config: any YAML or mapping is a Config or one ConfigError.

Run with `--hypothesis-show-statistics` to see how many examples each property tried.
"""

from __future__ import annotations

import math
import struct
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from prometheus_client.parser import text_string_to_metric_families

from overseer.codec import DecodeError, cdr, ros1
from overseer.config import ConfigError, config_from_dict, load_config
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.serve.exposition_formats import OPENMETRICS, TEXT
from overseer.serve.web_config import load_web_config, web_security_from_dict
from overseer.sources.ros1.tcpros import TcprosError, decode_header
from support.examples import examples
from support.oracle import parse_openmetrics
from support.rendering import Rendering
from support.strategies import damaged

Decoder = Callable[[bytes], DiagnosticArray]
DECODERS: dict[str, tuple[Decoder, Callable[[DiagnosticArray], bytes]]] = {
    "cdr": (cdr.decode_diagnostic_array, cdr.encode_diagnostic_array),
    "cdr-big-endian": (
        cdr.decode_diagnostic_array,
        lambda array: cdr.encode_diagnostic_array(array, little_endian=False),
    ),
    "ros1": (ros1.decode_diagnostic_array, ros1.encode_diagnostic_array),
}
STAMP_SECONDS = {  # builtin_interfaces/Time has int32 seconds; ROS 1 time has uint32
    "cdr": (-(2**31), 2**31 - 1),
    "cdr-big-endian": (-(2**31), 2**31 - 1),
    "ros1": (0, 2**32 - 1),
}
FUZZ = settings(max_examples=examples(1000), deadline=None, suppress_health_check=[HealthCheck.too_slow])
FUZZ_SLOW = settings(
    FUZZ, max_examples=examples(300)
)  # each example renders, parses and compares three expositions

# --- Messages ---

HOSTILE_TEXT = [
    '"',
    "\\",
    "\n",
    '\\"',
    "\\n",
    "\x00",
    "}",
    "{",
    "=",
    ",",
    "\r",
    "\t",
    "☃",
    "🤖",
    "\u2028",
    " ",
]
NUMBER_LIKE = [
    "NaN", "nan", "-nan", "inf", "-inf", "+Inf", "Infinity", "-Infinity", "1e308", "1e309", "-1e309",
    "4.9e-324", "-0", "0x10", "1_000", "12.5 V", " 3 ", "True", "False", "true", ".5", "5.", "+.5e-3 A", "",
]  # fmt: skip
text = st.one_of(
    st.text(max_size=24),
    st.lists(st.sampled_from(HOSTILE_TEXT), max_size=6).map("".join),
    st.sampled_from(NUMBER_LIKE),
)
values = st.lists(
    st.tuples(text, st.one_of(st.sampled_from(NUMBER_LIKE), st.floats().map(repr), text)), max_size=5
).map(tuple)
statuses = st.builds(
    DiagnosticStatus, st.integers(min_value=0, max_value=255), text, text, text, values
)  # levels beyond 3 are counted as invalid_level, never shown


def arrays(codec: str = "cdr") -> st.SearchStrategy[DiagnosticArray]:
    """DiagnosticArrays with hostile text and key-values, stamped as `codec` can carry."""
    low, high = STAMP_SECONDS[codec]
    return st.builds(
        DiagnosticArray,
        st.integers(min_value=low, max_value=high),
        st.integers(min_value=0, max_value=2**32 - 1),
        text,
        st.lists(statuses, max_size=6).map(tuple),
    )


def mutated(codec: str) -> st.SearchStrategy[bytes]:
    """A valid encoding, then damaged: bits flipped, cut, spliced, or a 32-bit word overwritten."""
    return arrays(codec).map(DECODERS[codec][1]).flatmap(damaged)


def decodes_or_raises_decode_error(decode: Decoder, payload: bytes) -> None:
    """Decode `payload`: a DiagnosticArray of str fields, or DecodeError; nothing else may escape."""
    try:
        array = decode(payload)
    except DecodeError:
        return
    assert isinstance(array, DiagnosticArray)
    for status in array.statuses:
        assert 0 <= status.level <= 255
        assert all(isinstance(field, str) for field in (status.name, status.message, status.hardware_id))


@pytest.mark.parametrize("codec", list(DECODERS))
@settings(FUZZ, max_examples=examples(500))
@given(data=st.data())
def test_damaged_payloads_raise_only_decode_error(codec: str, data: st.DataObject) -> None:
    decodes_or_raises_decode_error(DECODERS[codec][0], data.draw(mutated(codec)))


@pytest.mark.parametrize("codec", list(DECODERS))
@FUZZ
@given(payload=st.binary(max_size=2048))
@example(payload=b"\x00\x01\x00\x00" + b"\x00" * 8 + b"\x01\x00\x00\x00\x00" + b"\x00" * 3 + b"\xff" * 4)
@example(payload=b"\x00" * 12 + b"\xff\xff\xff\xff")
def test_random_payloads_raise_only_decode_error(codec: str, payload: bytes) -> None:
    decodes_or_raises_decode_error(DECODERS[codec][0], payload)


@pytest.mark.parametrize("codec", list(DECODERS))
@settings(FUZZ, max_examples=examples(300))
@given(data=st.data())
def test_every_message_survives_its_codec(codec: str, data: st.DataObject) -> None:
    decode, encode = DECODERS[codec]
    array = data.draw(arrays(codec))
    assert decode(encode(array)) == array


@FUZZ
@given(block=st.binary(max_size=512))
def test_tcpros_connection_headers_raise_only_tcpros_error(block: bytes) -> None:
    try:
        fields = decode_header(block)
    except TcprosError as error:
        assert error.reason == "handshake_error"
        return
    assert all(isinstance(k, str) and isinstance(v, str) for k, v in fields.items())


# --- Views ---


def cdr_with_raw_strings(statuses: list[tuple[int, bytes, bytes, list[tuple[bytes, bytes]]]]) -> bytes:
    """A CDR DiagnosticArray whose strings are raw bytes (invalid UTF-8 allowed); message is empty."""
    out = bytearray(cdr.ENCAPSULATION_CDR_LE + struct.pack("<iI", 0, 0))

    def put(raw: bytes) -> None:
        out.extend(b"\x00" * (-len(out) & 3))
        out.extend(struct.pack("<I", len(raw) + 1) + raw + b"\x00")

    def count(items: int) -> None:
        out.extend(b"\x00" * (-len(out) & 3))
        out.extend(struct.pack("<I", items))

    put(b"")
    count(len(statuses))
    for level, name, hardware_id, pairs in statuses:
        out.append(level)
        for field in (name, b"", hardware_id):
            put(field)
        count(len(pairs))
        for key, value in pairs:
            put(key)
            put(value)
    return bytes(out)


raw_text = st.one_of(st.binary(max_size=12), text.map(str.encode))
raw_statuses = st.lists(
    st.tuples(
        st.integers(min_value=0, max_value=3),
        raw_text,
        raw_text,
        st.lists(st.tuples(raw_text, st.sampled_from(NUMBER_LIKE).map(str.encode) | raw_text), max_size=3),
    ),
    max_size=4,
)
robot_names = st.one_of(st.text(min_size=1, max_size=16), st.sampled_from(["robot1", "site_a/robot7", 'r"1']))
fleets = st.lists(
    st.tuples(
        robot_names,
        st.one_of(arrays(), raw_statuses.map(cdr_with_raw_strings).map(cdr.decode_diagnostic_array)),
    ),
    min_size=1,
    max_size=6,
)
SMALL_CAPS = FleetLimits(
    max_robots=4, max_components_per_robot=5, max_values_per_component=3, max_string_length=16
)


def fed_model(fleet: list[tuple[str, DiagnosticArray]], limits: FleetLimits) -> FleetModel:
    """A fleet model that received `fleet`'s arrays in order."""
    model = FleetModel(limits)
    for robot, array in fleet:
        model.apply(robot, array, "dds", f"rt/{robot}/diagnostics_agg")
    return model


def render_both(model: FleetModel) -> tuple[bytes, bytes, bytes, bytes]:
    """Production's text and OpenMetrics, and the prometheus-client oracle's."""
    rendering = Rendering(model)
    return (
        rendering.fast(TEXT),
        rendering.oracle(TEXT),
        rendering.fast(OPENMETRICS),
        rendering.oracle(OPENMETRICS),
    )


def openmetrics_samples(exposition: bytes) -> list[tuple[str, tuple[tuple[str, str], ...], str]]:
    """Every sample of an OpenMetrics exposition, read by prometheus-client's strict parser."""
    return sorted(
        (sample.name, tuple(sorted(sample.labels.items())), repr(sample.value + 0.0))
        for family in parse_openmetrics(exposition.decode("utf-8"))
        for sample in family.samples
    )


def samples(exposition: bytes) -> list[tuple[str, tuple[tuple[str, str], ...], str]]:
    """Every sample of a text exposition as (name, labels, value), NaN and -0 made comparable."""
    return sorted(
        (sample.name, tuple(sorted(sample.labels.items())), repr(sample.value + 0.0))
        for family in text_string_to_metric_families(exposition.decode("utf-8"))
        for sample in family.samples
    )


@FUZZ_SLOW
@given(fleet=fleets, capped=st.booleans())
def test_any_fleet_renders_an_exposition_that_parses_back_to_the_model(
    fleet: list[tuple[str, DiagnosticArray]], capped: bool
) -> None:
    model = fed_model(fleet, SMALL_CAPS if capped else FleetLimits())
    fast, collected, openmetrics, collected_openmetrics = render_both(model)
    # The same samples as prometheus-client renders; bytes differ only in the sign of a zero (see below).
    assert samples(fast) == samples(collected)
    assert openmetrics_samples(openmetrics) == openmetrics_samples(collected_openmetrics)
    snapshot = model.snapshot()
    expected_components = {
        (robot.name, component.name, component.hardware_id)
        for robot in snapshot.robots
        for component in robot.components.values()
    }
    seen_components = set()
    seen_robots = set()
    for family in text_string_to_metric_families(fast.decode("utf-8")):
        for sample in family.samples:
            if sample.name == "ros_diagnostics_level":
                seen_components.add(
                    (sample.labels["robot"], sample.labels["component"], sample.labels["hardware_id"])
                )
                assert sample.value in (0, 1, 2, 3)
            elif sample.name == "ros_diagnostics_robot_up":
                seen_robots.add(sample.labels["robot"])
            elif sample.name == "ros_diagnostics_value":
                assert isinstance(sample.value, float)
    assert seen_components == expected_components
    assert seen_robots == {robot.name for robot in snapshot.robots}
    assert len(snapshot.robots) <= model.limits.max_robots
    families = {family.name for family in parse_openmetrics(openmetrics.decode("utf-8"))}
    assert "overseer_messages" in families


@FUZZ_SLOW
@given(fleet=fleets)
def test_caps_drop_and_count_never_exceed(fleet: list[tuple[str, DiagnosticArray]]) -> None:
    model = fed_model(fleet, SMALL_CAPS)
    snapshot = model.snapshot()
    assert len(snapshot.robots) <= SMALL_CAPS.max_robots
    for robot in snapshot.robots:
        assert len(robot.components) <= SMALL_CAPS.max_components_per_robot
        for component in robot.components.values():
            assert len(component.values) <= SMALL_CAPS.max_values_per_component
            assert len(component.name) <= SMALL_CAPS.max_string_length
    received = sum(count for (_, result), count in snapshot.message_counts.items() if result == "received")
    dropped = sum(count for (_, result), count in snapshot.message_counts.items() if result == "dropped")
    assert received + dropped == len(fleet)  # every message is counted once, one way or the other


def test_numeric_key_values_keep_nan_and_infinities_as_the_format_writes_them() -> None:
    array = DiagnosticArray(
        0, 0, "", (DiagnosticStatus(0, "/c", "", "", (("a", "NaN"), ("b", "inf"), ("c", "-Infinity"))),)
    )
    fast, *_ = render_both(fed_model([("r", array)], FleetLimits()))
    parsed = {
        sample.labels["key"]: sample.value
        for family in text_string_to_metric_families(fast.decode())
        for sample in family.samples
        if sample.name == "ros_diagnostics_value"
    }
    assert math.isnan(parsed["a"]) and parsed["b"] == math.inf and parsed["c"] == -math.inf


@settings(max_examples=examples(40), deadline=None)
@given(fleet=fleets)
def test_promtool_accepts_any_fleets_exposition(fleet: list[tuple[str, DiagnosticArray]]) -> None:
    fast, *_ = render_both(fed_model(fleet, FleetLimits()))
    result = subprocess.run(["promtool", "check", "metrics"], input=fast, capture_output=True, timeout=60)
    assert result.returncode == 0, (result.stdout + result.stderr).decode()


# --- Configuration ---

CONFIG_KEYS = [
    "web", "dds", "ros1", "fleet", "metrics", "shard", "log_level", "listen_address", "config_file",
    "enabled", "domains", "id", "robot_name", "topics", "prefer_aggregated", "loopback_only",
    "cyclonedds_uri", "robots", "name", "master_uri", "topic", "caller_id", "advertise_host",
    "reconnect_min", "reconnect_max", "poll_interval", "stale_after", "robot_timeout", "expire_after",
    "max_robots", "max_components_per_robot", "max_values_per_component", "max_string_length", "value_keys",
]  # fmt: skip
WEB_KEYS = [
    "tls_server_config", "http_server_config", "basic_auth_users", "cert_file", "key_file",
    "client_auth_type", "client_ca_file", "min_version", "max_version", "cipher_suites", "headers", "http2",
    "X-Frame-Options", "Content-Security-Policy", "NoClientCert", "RequireAndVerifyClientCert", "TLS13",
]  # fmt: skip
SCALAR_SAMPLES = [
    "5s", "1h30m", "250ms", "0s", "-1s", "9" * 400 + "s", "0/1", "1/0", "3/2", "debug", "INFO",
    "diagnostics_agg", ":9849", "[::1]:0", "host:99999", "http://10.0.0.5:11311", "ftp://x", ".*", "(",
    "robot1", "a\x00b", "TLS12", "TLS10", "deny", "nosniff",
]  # fmt: skip
SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.floats(),
    st.text(max_size=12),
    st.sampled_from(SCALAR_SAMPLES),
)


def documents(keys: list[str]) -> st.SearchStrategy[Any]:
    """Nested mappings and lists whose keys are mostly the real ones, with any values."""
    key = st.one_of(st.sampled_from(keys), st.text(max_size=8))
    return st.recursive(
        SCALARS,
        lambda children: st.lists(children, max_size=4) | st.dictionaries(key, children, max_size=6),
        max_leaves=24,
    )


@settings(FUZZ, max_examples=examples(500))
@given(
    raw=st.dictionaries(
        st.sampled_from(CONFIG_KEYS) | st.text(max_size=8), documents(CONFIG_KEYS), max_size=6
    )
)
@example(raw={"fleet": {"stale_after": 10**400}})
@example(raw={"dds": {"domains": [{"id": 10**30}]}})
def test_any_configuration_mapping_is_a_config_or_one_config_error(raw: dict[str, Any]) -> None:
    try:
        config_from_dict(raw)
    except ConfigError as error:
        assert "\n" not in str(error)


@settings(FUZZ, max_examples=examples(500))
@given(document=documents(CONFIG_KEYS) | st.text(max_size=200))
@example(document="[" * 5000)
@example(document="fleet: {stale_after: " + "9" * 5000 + "}")
@example(document="a: !!python/object:os.system 1")
def test_any_configuration_file_is_a_config_or_one_config_error(
    tmp_path_factory: pytest.TempPathFactory, document: Any
) -> None:
    path = tmp_path_factory.getbasetemp() / "fuzzed-overseer.yml"
    path.write_text(document if isinstance(document, str) else yaml.safe_dump(document), encoding="utf-8")
    try:
        load_config(path)
    except ConfigError as error:
        assert "\n" not in str(error)


@FUZZ
@given(raw=documents(WEB_KEYS))
@example(raw={"tls_server_config": {"cert_file": "a\x00b", "key_file": "k"}})
@example(raw={"basic_auth_users": {"u": "$2y$10$" + "a" * 53}})
def test_any_web_config_is_security_or_one_config_error(
    tmp_path_factory: pytest.TempPathFactory, raw: Any
) -> None:
    try:
        web_security_from_dict(raw, tmp_path_factory.getbasetemp())
    except ConfigError as error:
        assert "\n" not in str(error)


def test_a_huge_yaml_web_config_is_one_config_error(tmp_path: Path) -> None:
    path = tmp_path / "web.yml"
    for text_ in ("[" * 5000, "basic_auth_users: {a: " + "9" * 5000 + "}"):
        path.write_text(text_)
        with pytest.raises(ConfigError, match=r"^web\.config_file"):
            load_web_config(path)
