"""The inventory file: YAML of models and robots, read strictly into an `Inventory`.

Every error is one line naming the file, the robot (or model) and the key, as a configuration error
does; a duplicate key anywhere is one, since YAML would otherwise keep the last silently.
"""

from __future__ import annotations

import gc
import json
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from overseer.config.errors import ConfigError
from overseer.config.parsers import first_line, reject_unknown
from overseer.model import Expectation, Inventory, ListedRobot

# Labels Overseer's series, Prometheus's targets or the shipped alert rules carry already: an inventory
# label of the same name would collide with them when joined.
RESERVED_LABELS = frozenset(
    {
        "robot",
        "component",
        "hardware_id",
        "key",
        "level",
        "message",
        "transport",
        "result",
        "reason",
        "instance",
        "job",
        "alertname",
        "severity",
        "external_url",
        "le",
        "quantile",
        # the variables of the Icinga 2 hosts the push makes, beside which labels become variables
        "ros_robot",
        "dummy_state",
        "dummy_text",
    }
)
MAX_LABELS = 32
MAX_TEXT = 1024
MAX_AT_LEAST = 10_000
_LABEL_NAME = re.compile(r"[a-zA-Z_][a-zA-Z0-9_]*")
_TOP_KEYS = {"models", "robots"}
_MODEL_KEYS = {"labels", "expected"}
_ROBOT_KEYS = {"model", "labels", "expected"}
_EXPECTATION_KEYS = {"name", "prefix", "regex", "at_least"}


class InventoryError(ConfigError):
    """The inventory file cannot be used; the message names the file, the entry and the key."""


def load_inventory(path: str | Path) -> Inventory:
    """The inventory in the YAML file at `path`."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        reason = error.strerror if isinstance(error, OSError) else "not UTF-8 text"
        raise InventoryError(f"inventory.file: cannot read {str(path)!r}: {reason}") from None
    return parse_inventory(text, str(path))


def parse_inventory(text: str, source: str) -> Inventory:
    """The inventory in YAML `text` (JSON is YAML too, and read faster); `source` names it in errors."""
    try:
        loaded = _load(text)
    except (yaml.YAMLError, ValueError, RecursionError) as error:
        raise InventoryError(f"inventory.file {source!r}: not valid YAML: {first_line(error)}") from None
    try:
        return _inventory(loaded)
    except ConfigError as error:
        raise InventoryError(f"inventory.file {source!r}: {error}") from None


def _inventory(loaded: object) -> Inventory:
    if loaded is None:
        return Inventory()
    raw = _mapping(loaded, "the file")
    reject_unknown(raw, "", _TOP_KEYS)
    models = {
        _name(name, "models"): _model(entry, f"models.{_shown(name)}")
        for name, entry in _mapping(raw.get("models") or {}, "models").items()
    }
    robots = {}
    for name, entry in _mapping(raw.get("robots") or {}, "robots").items():
        robots[_name(name, "robots")] = _robot(entry, f"robots.{_shown(name)}", models)
    return Inventory(robots)


class _Model:
    """A model's labels and expected components, shared by its robots."""

    def __init__(self, labels: dict[str, str], expected: tuple[Expectation, ...]) -> None:
        self.labels = labels
        self.expected = expected


def _model(entry: object, key: str) -> _Model:
    raw = _mapping(entry or {}, key)
    reject_unknown(raw, key + ".", _MODEL_KEYS)
    return _Model(
        _labels(raw.get("labels"), key + ".labels"), _expected(raw.get("expected"), key + ".expected")
    )


def _robot(entry: object, key: str, models: Mapping[str, _Model]) -> ListedRobot:
    raw = _mapping(entry or {}, key)
    reject_unknown(raw, key + ".", _ROBOT_KEYS)
    labels: dict[str, str] = {}
    expected: tuple[Expectation, ...] = ()
    if "model" in raw:
        model_name = raw["model"]
        model = models.get(model_name) if isinstance(model_name, str) else None
        if model is None:
            known = ", ".join(sorted(models)) or "none in models:"
            raise ConfigError(f"{key}.model: unknown model {model_name!r} (known: {known})")
        labels = {"model": model_name, **model.labels}
        expected = model.expected
    labels.update(_labels(raw.get("labels"), key + ".labels"))
    if len(labels) > MAX_LABELS:
        raise ConfigError(f"{key}.labels: at most {MAX_LABELS} labels, got {len(labels)} with its model's")
    own = _expected(raw.get("expected"), key + ".expected")
    return ListedRobot(tuple(sorted(labels.items())), expected + own if own else expected)


def _labels(value: object, key: str) -> dict[str, str]:
    if value is None:
        return {}
    raw = _mapping(value, key)
    if len(raw) > MAX_LABELS:
        raise ConfigError(f"{key}: at most {MAX_LABELS} labels, got {len(raw)}")
    labels = {}
    for name, label_value in raw.items():
        if not isinstance(name, str) or not _LABEL_NAME.fullmatch(name) or name.startswith("__"):
            raise ConfigError(
                f"{key}: {name!r} is not a label name "
                "(letters, digits and _, not starting with a digit or __)"
            )
        if name in RESERVED_LABELS or name.startswith("overseer_"):
            raise ConfigError(
                f"{key}.{name}: {name!r} is a label of Overseer's own series; name it otherwise"
            )
        if not isinstance(label_value, str) or not label_value:
            hint = " (quote it in YAML)" if isinstance(label_value, int | float) else ""
            raise ConfigError(f"{key}.{name}: expected a non-empty string{hint}, got {label_value!r}")
        if len(label_value) > MAX_TEXT:
            raise ConfigError(f"{key}.{name}: at most {MAX_TEXT} characters, got {len(label_value)}")
        labels[name] = label_value
    return labels


def _expected(value: object, key: str) -> tuple[Expectation, ...]:
    if value is None:
        return ()
    if not isinstance(value, list):
        raise ConfigError(f"{key}: expected a list of component names or mappings, got {value!r}")
    return tuple(_expectation(item, f"{key}[{index}]") for index, item in enumerate(value))


def _expectation(item: object, key: str) -> Expectation:
    if isinstance(item, str):
        return Expectation(_text(item, key), exact=item)
    raw = _mapping(item, key)
    reject_unknown(raw, key + ".", _EXPECTATION_KEYS)
    kinds = [kind for kind in ("name", "prefix", "regex") if kind in raw]
    if len(kinds) != 1:
        raise ConfigError(f"{key}: expected one of name, prefix or regex, got {', '.join(kinds) or 'none'}")
    [kind] = kinds
    text = _text(raw[kind], f"{key}.{kind}")
    at_least = raw.get("at_least", 1)
    if isinstance(at_least, bool) or not isinstance(at_least, int) or not 1 <= at_least <= MAX_AT_LEAST:
        raise ConfigError(
            f"{key}.at_least: expected a whole number from 1 to {MAX_AT_LEAST}, got {at_least!r}"
        )
    if kind == "name":
        if at_least != 1:
            raise ConfigError(f"{key}.at_least: one name is one component; give a prefix or a regex")
        return Expectation(text, exact=text)
    if kind == "prefix":
        return Expectation(text + "*", prefix=text, at_least=at_least)
    try:
        pattern = re.compile(text)
    except (re.error, RecursionError, OverflowError) as error:
        raise ConfigError(f"{key}.regex: not a regular expression: {first_line(error)}") from None
    return Expectation(text, pattern=pattern, at_least=at_least)


def _mapping(value: object, key: str) -> dict[Any, Any]:
    if not isinstance(value, dict):
        raise ConfigError(f"{key}: expected a mapping, got {value!r}"[:300])
    return value


def _name(name: object, where: str) -> str:
    if not isinstance(name, str) or not name or not name.isprintable() or len(name) > MAX_TEXT:
        raise ConfigError(f"{where}: {name!r} is not a name (a printable string)"[:300])
    return name


def _text(value: object, key: str) -> str:
    if not isinstance(value, str) or not value or len(value) > MAX_TEXT:
        raise ConfigError(f"{key}: expected a string of 1 to {MAX_TEXT} characters, got {value!r}"[:300])
    return value


def _shown(name: object) -> str:
    return name if isinstance(name, str) and name.isprintable() and name else repr(name)


def _load(text: str) -> object:
    """The document in `text`: as JSON when it is one, else as YAML; a key given twice is an error.

    The cyclic garbage collector pauses meanwhile: an inventory of 10,000 robots is some 150,000 YAML
    nodes, none of them in a cycle, and the collections their creation sets off took two thirds of the
    time (in an exporter that holds a large fleet, more).
    """
    collecting = gc.isenabled()
    gc.disable()
    try:
        if text.lstrip().startswith("{"):
            try:
                return json.loads(text, object_pairs_hook=_json_mapping)
            except _DuplicateKey:
                raise
            except ValueError:
                pass  # not JSON after all (a YAML flow mapping): YAML reads it below
        root = yaml.compose(
            text, Loader=yaml.CSafeLoader if hasattr(yaml, "CSafeLoader") else yaml.SafeLoader
        )
        try:
            return _built(root)
        except _MergeKey:  # `<<:` merges need the full constructor; rare in an inventory
            return yaml.load(text, Loader=_StrictLoader)
    finally:
        if collecting:
            gc.enable()


class _MergeKey(Exception):
    """A YAML merge key (`<<`), which `_built` leaves to the full constructor."""


def _built(node: yaml.Node | None) -> object:
    """The value of a composed YAML node, built directly (several times faster than YAML's constructor).

    Strings and nulls here, other scalars by YAML's safe constructor; a key given twice is refused (YAML
    itself would keep the last one).
    """
    if node is None:
        return None
    kind = type(node)
    if kind is yaml.ScalarNode:
        if node.tag == _STRING_TAG:
            return node.value
        if node.tag == _NULL_TAG:
            return None
        return _SCALARS.construct_object(node, deep=True)
    if kind is yaml.SequenceNode:
        return [_built(item) for item in node.value]
    if kind is not yaml.MappingNode:
        return _SCALARS.construct_object(node, deep=True)  # raises for what a safe load refuses
    mapping: dict[Any, Any] = {}
    for key_node, value_node in node.value:
        if key_node.tag == _MERGE_TAG:
            raise _MergeKey
        key = key_node.value if key_node.tag == _STRING_TAG else _built(key_node)
        try:
            duplicate = key in mapping
        except TypeError:  # an unhashable key (a mapping as a key): as the safe constructor says
            raise yaml.constructor.ConstructorError(
                None, None, "found an unhashable key", key_node.start_mark
            ) from None
        if duplicate:
            raise yaml.constructor.ConstructorError(
                None, None, f"{key!r} is given twice", key_node.start_mark
            )
        mapping[key] = _built(value_node)
    return mapping


class _DuplicateKey(ValueError):
    """A key given twice in one mapping."""


def _json_mapping(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    mapping = dict(pairs)
    if len(mapping) < len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise _DuplicateKey(f"{key!r} is given twice")
            seen.add(key)
    return mapping


class _StrictLoader(yaml.CSafeLoader if hasattr(yaml, "CSafeLoader") else yaml.SafeLoader):  # type: ignore[misc]
    """YAML's safe loader (its C parser where there is one), refusing a key given twice in a mapping."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[object] = set()
        for key_node, _ in node.value:
            if key_node.tag == _MERGE_TAG:
                continue  # merged keys may be overridden: that is what a merge is for
            # A string key is compared as written (cheap); any other is constructed to be compared.
            key = (
                key_node.value if key_node.tag == _STRING_TAG else self.construct_object(key_node, deep=True)
            )
            try:
                duplicate = key in seen
                seen.add(key)
            except TypeError:  # an unhashable key: the safe constructor says so itself below
                continue
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    None, None, f"{key!r} is given twice", key_node.start_mark
                )
        return super().construct_mapping(node, deep)  # type: ignore[no-any-return]


_STRING_TAG = "tag:yaml.org,2002:str"
_NULL_TAG = "tag:yaml.org,2002:null"
_MERGE_TAG = "tag:yaml.org,2002:merge"
_SCALARS = yaml.constructor.SafeConstructor()  # ints, booleans, floats, timestamps: as a safe load has them
