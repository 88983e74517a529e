"""Debian's Prometheus on loopback for tests, the shipped configs aimed at it, and PromQL and rule reading."""

from __future__ import annotations

import json
import re
import subprocess
import time
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import yaml

from testbed.paths import REPO
from testbed.ports import free_port
from testbed.processes import RunningProcess, spawn

DEPLOY_PROMETHEUS = REPO / "deploy" / "prometheus"
EXPORTER_JOB = "overseer"

_DURATION_PART = re.compile(r"(\d+)(ms|s|m|h|d|w|y)")
_DURATION_SECONDS = {"ms": 0.001, "s": 1, "m": 60, "h": 3600, "d": 86400, "w": 604800, "y": 31536000}
_STRING = r""""(?:[^"\\]|\\.)*"|'(?:[^'\\]|\\.)*'|`[^`]*`"""
_PROMQL_TOKEN = re.compile(
    rf"""(?P<string>{_STRING})
      |(?P<matchers>\{{(?:[^{{}}"'`]|{_STRING})*\}})
      |(?P<range>\[[^\]]*\])
      |(?P<grouping>\b(?:by|without|on|ignoring|group_left|group_right)\s*\([^)]*\))
      |(?P<number>\d[\w.]*)
      |(?P<name>[a-zA-Z_:][\w:]*)
      |(?P<space>\s+)
      |(?P<other>.)""",
    re.VERBOSE | re.DOTALL,
)
_KEYWORDS = {"and", "or", "unless", "by", "without", "on", "ignoring", "group_left", "group_right", "bool"}
_KEYWORDS |= {"offset", "inf", "nan"}


def parse_duration(text: str) -> float:
    """Seconds in a Prometheus duration such as `1m30s`."""
    parts = _DURATION_PART.findall(text)
    if not parts or "".join(number + unit for number, unit in parts) != text:
        raise ValueError(f"not a Prometheus duration: {text!r}")
    return sum(int(number) * _DURATION_SECONDS[unit] for number, unit in parts)


@dataclass(frozen=True)
class Selector:
    """A vector selector of a PromQL expression: the metric name and its label matchers (`{...}` or empty)."""

    metric: str
    matchers: str


def selectors(expr: str) -> list[Selector]:
    """Every vector selector with a metric name in `expr`, in order."""
    tokens = [(match.lastgroup, match.group()) for match in _PROMQL_TOKEN.finditer(expr)]
    tokens = [token for token in tokens if token[0] != "space"]
    found = []
    for index, (kind, text) in enumerate(tokens):
        if kind != "name" or text.lower() in _KEYWORDS:
            continue
        following = tokens[index + 1] if index + 1 < len(tokens) else ("", "")
        if following[1] == "(" or following[0] == "grouping":  # a function, or `sum by (...) (...)`
            continue
        found.append(Selector(text, following[1] if following[0] == "matchers" else ""))
    return found


def load_rules(path: Path) -> list[dict[str, Any]]:
    """Every rule (alerting and recording) of a Prometheus rule file, in file order."""
    document = yaml.safe_load(path.read_text(encoding="utf-8"))
    return [rule for group in document["groups"] for rule in group["rules"]]


@dataclass
class RunningServer(RunningProcess):
    """A running server of Prometheus' family and its base URL."""

    url: str


ServerT = TypeVar("ServerT", bound=RunningServer)


@dataclass
class Prometheus(RunningServer):
    """A running Prometheus server."""

    def api(self, path: str, **params: str) -> Any:
        """The `data` of a successful GET /api/v1/`path`."""
        query = urllib.parse.urlencode(params)
        with urllib.request.urlopen(f"{self.url}/api/v1/{path}?{query}", timeout=10) as response:
            body = json.load(response)
        if body["status"] != "success":
            raise AssertionError(f"Prometheus API {path} {params}: {body}")
        return body["data"]

    def query(self, expr: str) -> list[dict[str, Any]]:
        """The instant vector `expr` evaluates to now."""
        result: list[dict[str, Any]] = self.api("query", query=expr)["result"]
        return result

    def query_range(self, expr: str, seconds: float, step: str = "1s") -> list[dict[str, Any]]:
        """The series `expr` evaluates to over the last `seconds`."""
        end = time.time()
        data = self.api("query_range", query=expr, start=str(end - seconds), end=str(end), step=step)
        result: list[dict[str, Any]] = data["result"]
        return result

    def series(self, selector: str) -> list[dict[str, str]]:
        """The label sets of the series `selector` matches."""
        result: list[dict[str, str]] = self.api("series", **{"match[]": selector})
        return result

    def alerts(self) -> list[dict[str, Any]]:
        """The alerts the rules hold now, pending or firing."""
        result: list[dict[str, Any]] = self.api("alerts")["alerts"]
        return result


def shipped_config(
    name: str,
    exporter_urls: Sequence[str],
    alertmanager_url: str | None = None,
    interval: str | None = None,
) -> dict[str, Any]:
    """A shipped deploy/prometheus config, pointed at test servers; its rule files stay the shipped ones.

    Only the overseer scrape job is kept, scraping every one of `exporter_urls`; `interval`, when given,
    replaces the scrape and evaluation interval.
    """
    path = DEPLOY_PROMETHEUS / name
    config: dict[str, Any] = yaml.safe_load(path.read_text(encoding="utf-8"))
    config["rule_files"] = [str((path.parent / rule_file).resolve()) for rule_file in config["rule_files"]]
    config["scrape_configs"] = [job for job in config["scrape_configs"] if job["job_name"] == EXPORTER_JOB]
    targets = [_host_port(url) for url in exporter_urls]
    config["scrape_configs"][0]["static_configs"] = [{"targets": targets}]
    if alertmanager_url is None:
        del config["alerting"]
    else:
        config["alerting"]["alertmanagers"] = [
            {"static_configs": [{"targets": [_host_port(alertmanager_url)]}]}
        ]
    if interval is not None:
        config["global"].update(
            scrape_interval=interval, scrape_timeout=interval, evaluation_interval=interval
        )
    return config


def _host_port(url: str) -> str:
    return urllib.parse.urlsplit(url).netloc


def wait_until_ready(server: RunningProcess, url: str, timeout: float = 30.0) -> None:
    """Wait for GET `url` to answer 200, failing early if the server exits."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if server.process.poll() is not None:
            raise RuntimeError(f"{url}: server exited with {server.process.returncode}:\n{server.log()}")
        try:
            with urllib.request.urlopen(url, timeout=1.0):
                return
        except (urllib.error.URLError, ConnectionError, TimeoutError):
            time.sleep(0.1)
    raise TimeoutError(f"{url} not ready after {timeout}s:\n{server.log()}")


@contextmanager
def running_prometheus(tmp_path: Path, config: dict[str, Any]) -> Iterator[Prometheus]:
    """Run Debian's `prometheus` on loopback with `config` and temporary storage until the block ends."""
    with running_server(tmp_path, Prometheus, "prometheus", config, "--storage.tsdb.path") as prometheus:
        yield prometheus


@contextmanager
def running_store(tmp_path: Path, config: dict[str, Any] | None = None) -> Iterator[Prometheus]:
    """Run Debian's `prometheus` with `config` (none: it scrapes nothing), storing what agents send it."""
    flags = ("--storage.tsdb.path", "--web.enable-remote-write-receiver")
    with running_server(tmp_path, Prometheus, "prometheus", config or {}, *flags) as store:
        yield store


@contextmanager
def running_agent(tmp_path: Path, config: dict[str, Any]) -> Iterator[Prometheus]:
    """Run Debian's `prometheus` in agent mode: it scrapes as `config` says, for its `remote_write` only.

    An agent answers no query: read what it scraped from the store it sends to.
    """
    flags = ("--storage.agent.path", "--enable-feature=agent")
    with running_server(tmp_path, Prometheus, "prometheus", config, *flags) as agent:
        yield agent


@contextmanager
def running_victoria_metrics(tmp_path: Path) -> Iterator[Prometheus]:
    """Run Debian's single-node `victoria-metrics` on loopback: a store agents send to (`/api/v1/write`).

    It answers Prometheus's query API; its queries see samples as they arrive (no 30 s latency offset)
    and are not cached, so that a figure read twice is read from the samples each time.
    """
    port = free_port()
    directory = tmp_path / f"victoria-metrics-{port}"
    directory.mkdir(parents=True, exist_ok=True)
    args = [
        "victoria-metrics",
        f"-httpListenAddr=127.0.0.1:{port}",
        f"-storageDataPath={directory / 'data'}",
        "-retentionPeriod=1d",
        "-search.latencyOffset=0s",
        "-search.disableCache",
    ]
    log_path = directory / "victoria-metrics.log"
    store = Prometheus(spawn(args, log_path), log_path, f"http://127.0.0.1:{port}")
    with serving(store, "/health"):
        yield store


@contextmanager
def running_server(
    tmp_path: Path,
    server_class: Callable[[subprocess.Popen[bytes], Path, str], ServerT],
    program: str,
    config: dict[str, Any],
    storage_flag: str,
    *flags: str,
    port: int | None = None,
) -> Iterator[ServerT]:
    """Run `program` of Prometheus' family on loopback (on `port`, or a free one) with `config` until the end.

    Its storage goes under `tmp_path` (`storage_flag`), kept across runs on the same port; it is ready
    when GET /-/ready answers.
    """
    port = free_port() if port is None else port
    directory = tmp_path / f"{program}-{port}"
    directory.mkdir(parents=True, exist_ok=True)
    config_path = directory / f"{program}.yml"
    config_path.write_text(yaml.safe_dump(config), encoding="utf-8")
    args = [
        program,
        f"--config.file={config_path}",
        f"{storage_flag}={directory / 'data'}",
        f"--web.listen-address=127.0.0.1:{port}",
        *flags,
    ]
    log_path = directory / f"{program}.log"
    server = server_class(spawn(args, log_path), log_path, f"http://127.0.0.1:{port}")
    with serving(server, "/-/ready"):
        yield server


@contextmanager
def serving(server: RunningServer, ready_path: str) -> Iterator[None]:
    """Wait for `server` to answer GET `ready_path`, and stop it when the block ends, or if it never does."""
    try:
        wait_until_ready(server, server.url + ready_path)
        yield
    finally:
        server.stop()
