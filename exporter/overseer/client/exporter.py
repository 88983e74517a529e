"""The exporter's HTTP API as one client: its address, TLS and credentials, and a deadline per request.

`check_ros_diagnostics` and `overseer maintenance` reach the exporter through it, with the same options:
`-H`/`-p` or `--url`, basic auth from `--authorization-file`, `-a` or the `CHECK_ROS_DIAGNOSTICS_AUTH`
variable, `--ca-file`, `--insecure`, `--client-cert`, `--client-key`, `-t`. Every failure is a
`ClientError`. Standard library only, and cheap: the check starts once per check. The Icinga 2 and
Alertmanager clients of `push/` are their own: they talk to other servers, over connections they keep
alive between requests.
"""

from __future__ import annotations

import os

from overseer.client.http import Answer, ClientError, Tls, parse_url, quote_path, request

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing (the check's start-up)
if TYPE_CHECKING:
    from typing import Any

AUTH_VARIABLE = "CHECK_ROS_DIAGNOSTICS_AUTH"
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 9849
DEFAULT_TIMEOUT_SECONDS = 10.0


class ExporterClient:
    """Requests to one exporter: its base URL, credentials (`user:password`) and TLS, `timeout` each."""

    __slots__ = ("authorization", "timeout", "tls", "url", "user_agent")

    def __init__(
        self,
        url: str,
        timeout: float = DEFAULT_TIMEOUT_SECONDS,
        authorization: str = "",
        tls: Tls | None = None,
        user_agent: str = "overseer",
    ) -> None:
        """Keep the fields; `url` is the exporter's base URL (`exporter_url` makes one from options)."""
        self.url = url.rstrip("/")
        self.timeout = timeout
        self.authorization = authorization
        self.tls = tls or Tls()
        self.user_agent = user_agent

    def url_of(self, path: str, *names: str) -> str:
        """The URL of `path` on the exporter, with each of `names` appended as a quoted path segment."""
        return self.url + path + "".join("/" + quote_path(name) for name in names)

    def get(self, path: str, *names: str) -> Answer:
        """GET `path` (with `names` appended, quoted)."""
        return self.send("GET", self.url_of(path, *names))

    def send(self, method: str, url: str, body: bytes | None = None) -> Answer:
        """`method` to `url` with a JSON `body`; the answer whatever its status."""
        return request(method, url, self.timeout, self.authorization, self.tls, body, self.user_agent)

    def call(self, method: str, path: str, document: object = None) -> dict[str, Any]:
        """The JSON document the API answers to `method` on `path` with `document` as the body.

        ClientError saying the API's own error when it refuses (any status but 2xx).
        """
        import json  # the check never calls: only the commands pay for it

        url = self.url_of(path)
        answer = self.send(method, url, None if document is None else json.dumps(document).encode())
        try:
            answered = json.loads(answer.body)
        except ValueError:
            answered = None
        if not isinstance(answered, dict):
            raise ClientError(f"HTTP {answer.status} {answer.reason} from {url}: the answer is not JSON")
        if not 200 <= answer.status < 300:
            raise ClientError(f"HTTP {answer.status} from {url}: {answered.get('error', 'no explanation')}")
        return answered


def exporter_url(url: str = "", host: str = "", port: str = "") -> str:
    """The exporter's base URL, from `--url` or from `-H` and `-p` (default 127.0.0.1:9849)."""
    if url:
        if host or port:
            raise ClientError("give either --url or -H/-p, not both")
        parse_url(url)
        return url.rstrip("/")
    host = host or DEFAULT_HOST
    port = port or str(DEFAULT_PORT)
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ClientError(f"invalid port {port!r}: give a number from 1 to 65535")
    if ":" in host and not host.startswith("["):
        host = f"[{host}]"
    return f"http://{host}:{port}"


def credentials(path: str = "", given: str = "") -> str:
    """`user:password` for basic auth from a file's first line, the command line or the environment.

    '' for none. The file (`--authorization-file`) and `-a` exclude each other; without either,
    `CHECK_ROS_DIAGNOSTICS_AUTH` is read.
    """
    if path and given:
        raise ClientError("give either --authorization-file or -a/--authorization, not both")
    if path:
        source = f"--authorization-file {path!r}"
        try:
            with open(path, encoding="utf-8") as file:
                text = file.readline().rstrip("\r\n")
        except OSError as error:
            raise ClientError(f"cannot read {source}: {error.strerror}") from None
        except UnicodeDecodeError:
            raise ClientError(f"cannot read {source}: not UTF-8 text") from None
    elif given:
        source, text = "-a/--authorization", given
    else:
        source, text = AUTH_VARIABLE, os.environ.get(AUTH_VARIABLE, "")
    if text and ":" not in text:
        raise ClientError(f"{source}: expected USER:PASSWORD")  # never echo what may be a password
    return text


def timeout_seconds(text: str) -> float:
    """`-t`'s seconds; ClientError unless a positive number below a day."""
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not 0 < value < 86400:
        raise ClientError(f"invalid --timeout {text!r}: give seconds, more than 0 and less than a day")
    return value
