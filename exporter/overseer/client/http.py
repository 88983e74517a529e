"""HTTP for the exporter's API: one request over a plain socket, with TLS and basic auth when asked.

`urllib.request` and `http.client` import the email package and ssl, which alone take longer than
starting Python, and `check_ros_diagnostics` starts once per check; the exporter's API needs one request
and a body, so HTTP/1.0 over a socket does it (an HTTP/1.0 request gets neither chunked encoding nor
keep-alive). Even `socket.py` costs a sixth of Python's start-up in enums and selectors, so plain http
uses the `_socket` C module it wraps; `socket`, `ssl` and `binascii` are imported only when https or
credentials need them. Credentials are sent, never printed. Every failure is a `ClientError`.
"""

import _socket
import time

_MAX_ANSWER_BYTES = 64 * 1024 * 1024


class ClientError(Exception):
    """The exporter could not be asked, or did not answer as its API does; the text says why."""


_UNRESERVED = frozenset(b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-._~/")


class Answer:
    """An HTTP answer: status code, reason phrase and body."""

    __slots__ = ("body", "reason", "status")

    def __init__(self, status: int, reason: str, body: bytes) -> None:
        """Keep the fields."""
        self.status = status
        self.reason = reason
        self.body = body


class Tls:
    """How to talk TLS: the CA to verify the exporter with (or `insecure`), a client certificate and key."""

    __slots__ = ("ca_file", "client_cert", "client_key", "insecure")

    def __init__(
        self, ca_file: str = "", insecure: bool = False, client_cert: str = "", client_key: str = ""
    ) -> None:
        """Keep the fields; empty strings mean the system's CAs and no client certificate."""
        self.ca_file = ca_file
        self.insecure = insecure
        self.client_cert = client_cert
        self.client_key = client_key


class Url:
    """An http(s) URL split into what a request needs."""

    __slots__ = ("host", "path", "port", "tls")

    def __init__(self, tls: bool, host: str, port: int, path: str) -> None:
        """Keep the fields; `host` is bare (no IPv6 brackets), `path` starts with '/'."""
        self.tls = tls
        self.host = host
        self.port = port
        self.path = path

    def authority(self) -> str:
        """`host:port` as the Host header and messages write it (IPv6 in brackets)."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{host}:{self.port}"


def parse_url(url: str) -> Url:
    """Split `scheme://host[:port][/path]`; ClientError when it is not an http(s) URL without credentials."""
    scheme, separator, rest = url.partition("://")
    scheme = scheme.lower()
    if not separator or scheme not in ("http", "https"):
        raise ClientError(f"invalid URL {url!r}: it must start with http:// or https://")
    authority, slash, path = rest.partition("/")
    if "@" in authority:
        raise ClientError("invalid URL: give credentials with -a/--authorization, not in the URL")
    host, port_text = split_host_port(authority, "443" if scheme == "https" else "80")
    if not host:
        raise ClientError(f"invalid URL {url!r}: no host")
    if not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise ClientError(f"invalid URL {url!r}: bad port {port_text!r}")
    return Url(scheme == "https", host, int(port_text), slash + path or "/")


def split_host_port(authority: str, default_port: str) -> tuple[str, str]:
    """`host[:port]` or `[v6]:port` → (bare host, port text)."""
    if authority.startswith("["):
        host, _, after = authority[1:].partition("]")
        return host, after.removeprefix(":") or default_port
    host, _, port = authority.partition(":")
    return host, port or default_port


def quote_path(text: str) -> str:
    """`text` percent-encoded for a URL path, keeping '/' (robot names may contain it)."""
    return "".join(chr(byte) if byte in _UNRESERVED else f"%{byte:02X}" for byte in text.encode("utf-8"))


def request(
    method: str,
    url: str,
    timeout: float,
    authorization: str = "",
    tls: Tls | None = None,
    body: bytes | None = None,
    user_agent: str = "overseer",
) -> Answer:
    """Send `method` (with a JSON `body`) to `url` and read the answer, within `timeout` seconds in all.

    ClientError naming the URL when no HTTP answer comes back. The deadline bounds connecting, sending and
    every read; only a DNS lookup that hangs can outlast it.
    """
    target = parse_url(url)
    deadline = time.monotonic() + timeout
    try:
        stream = connect(target, deadline, tls or Tls())
        try:
            stream.sendall(request_bytes(target, authorization, method, body, user_agent))
            return parse_answer(read_all(stream, deadline), url)
        finally:
            stream.close()
    except _socket.gaierror as error:
        raise ClientError(f"cannot resolve {target.host!r}: {error.strerror}") from None
    except TimeoutError:
        raise ClientError(f"timeout: no complete answer from {url} within {timeout:g} s") from None
    except ConnectionRefusedError:
        raise ClientError(f"exporter unreachable at {url}: connection refused") from None
    except OSError as error:
        if target.tls and type(error).__module__ == "ssl":  # ssl is imported when it can have raised
            raise ClientError(f"TLS error with {url}: {tls_reason(error)}") from None
        raise ClientError(f"exporter unreachable at {url}: {error.strerror or error}") from None


def remaining(deadline: float) -> float:
    """Seconds left until `deadline`; TimeoutError when none are."""
    left = deadline - time.monotonic()
    if left <= 0:
        raise TimeoutError
    return left


def tls_reason(error: OSError) -> str:
    """What went wrong in TLS, without OpenSSL's source locations: `certificate verify failed: ...`."""
    verify_message = getattr(error, "verify_message", "")
    if verify_message:
        return f"certificate verify failed: {verify_message}"
    reason = getattr(error, "reason", "")
    return str(reason).lower().replace("_", " ") if reason else str(error)


def connect(target: Url, deadline: float, tls: Tls) -> _socket.socket:
    """A connection to the first of `target`'s addresses that accepts one, inside TLS for https."""
    # An ASCII host goes to getaddrinfo as bytes, which spares importing the IDNA codec.
    host = target.host.encode("ascii") if target.host.isascii() else target.host
    error = OSError(f"no address for {target.host}")
    for family, kind, protocol, _, address in _socket.getaddrinfo(host, target.port, 0, _socket.SOCK_STREAM):
        sock = _socket.socket(family, kind, protocol)
        try:
            sock.settimeout(remaining(deadline))
            sock.connect(address)
        except OSError as refused:
            sock.close()
            error = refused.with_traceback(None)  # its traceback holds this frame, which would hold it
            continue
        return wrap_tls(sock, target.host, deadline, tls) if target.tls else sock
    try:
        raise error
    finally:
        del error  # a raised exception its own frame names is a reference cycle, freed only by a collection


def wrap_tls(sock: _socket.socket, host: str, deadline: float, tls: Tls) -> _socket.socket:
    """`sock` inside TLS after a handshake before `deadline`, verifying the certificate unless insecure."""
    import socket  # only https pays for these
    import ssl

    try:
        context = ssl.create_default_context(cafile=tls.ca_file or None)
    except OSError as error:
        raise ClientError(f"cannot use --ca-file {tls.ca_file!r}: {file_error(error)}") from None
    if tls.client_cert:
        try:
            context.load_cert_chain(tls.client_cert, tls.client_key or None)
        except OSError as error:
            raise ClientError(f"cannot use --client-cert {tls.client_cert!r}: {file_error(error)}") from None
    if tls.insecure:
        context.check_hostname = False
        context.verify_mode = ssl.CERT_NONE
    plain = socket.socket(fileno=sock.detach())
    plain.settimeout(remaining(deadline))
    return context.wrap_socket(plain, server_hostname=host)


def file_error(error: OSError) -> str:
    """Why a certificate, key or CA file could not be used."""
    return error.strerror or str(getattr(error, "reason", "") or error)


def request_bytes(
    target: Url,
    credentials: str,
    method: str = "GET",
    body: bytes | None = None,
    user_agent: str = "overseer",
) -> bytes:
    """The HTTP/1.0 request for `target`, with basic auth when `credentials` is `user:password`.

    A `body` goes as JSON (`Content-Type: application/json`).
    """
    lines = [
        f"{method} {target.path} HTTP/1.0",
        f"Host: {target.authority()}",
        "Accept: application/json",
        f"User-Agent: {user_agent}",
    ]
    if credentials:
        import binascii  # only basic auth pays for it

        token = binascii.b2a_base64(credentials.encode("utf-8"), newline=False).decode("ascii")
        lines.append(f"Authorization: Basic {token}")
    if body is not None:
        lines += ["Content-Type: application/json", f"Content-Length: {len(body)}"]
    return ("\r\n".join(lines) + "\r\n\r\n").encode("utf-8") + (body or b"")


def read_all(stream: _socket.socket, deadline: float) -> bytes:
    """Everything the server sends until it closes the connection, before `deadline`, up to a sane limit."""
    chunks = []
    size = 0
    while True:
        stream.settimeout(remaining(deadline))
        chunk = stream.recv(65536)
        if not chunk:
            break
        size += len(chunk)
        if size > _MAX_ANSWER_BYTES:
            raise ClientError(f"answer larger than {_MAX_ANSWER_BYTES // (1024 * 1024)} MiB")
        chunks.append(chunk)
    return b"".join(chunks)


def parse_answer(raw: bytes, url: str) -> Answer:
    """Status line, headers and body of a raw HTTP answer; ClientError when it is not one."""
    head, separator, body = raw.partition(b"\r\n\r\n")
    lines = head.decode("iso-8859-1").split("\r\n")
    version, _, status = lines[0].partition(" ")
    code, _, reason = status.partition(" ")
    if not separator or not version.startswith("HTTP/") or not code.isdigit():
        raise ClientError(f"no HTTP answer from {url}")
    length = header(lines[1:], "content-length")
    if length.isdigit():
        if len(body) < int(length):
            raise ClientError(f"answer from {url} cut short: {len(body)} of {length} bytes")
        body = body[: int(length)]
    return Answer(int(code), reason.strip(), body)


def header(lines: list[str], name: str) -> str:
    """The value of header `name` (lower case) among `lines`, or ''."""
    for line in lines:
        key, _, value = line.partition(":")
        if key.strip().lower() == name:
            return value.strip()
    return ""
