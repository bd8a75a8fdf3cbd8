"""The Foxglove bridge's front door: each WebSocket handshake is checked before foxglove-sdk's.

foxglove-sdk 0.30's server accepts any Origin (a web page open in the user's browser could
connect and publish) and only the `foxglove.sdk.v1` subprotocol (Lichtblick, Foxglove's own
@foxglove/ws-protocol client and the ROS foxglove_bridge 0.x offer the same protocol as
`foxglove.websocket.v1`), and neither can be configured. So the gate listens on the user's
host:port, reads the HTTP upgrade request and
- answers 403 to an Origin that is not allowed (browsers always send the page's Origin and a
  script cannot change it: `origin_allowed`);
- answers 400 unless one of the two protocol names is offered;
- otherwise hands the request to the SDK's server, offering `foxglove.sdk.v1`, gives the client
  back the name it offered, and relays bytes both ways (the SDK keeps framing, backlogs and slow
  clients; a slow client still only loses data messages).
The SDK's server listens on a loopback port of its own that speaks only TLS, with a certificate
made at start-up that only the gate trusts: a browser cannot open it (an untrusted certificate
fails a page's WebSocket), so no page gets around the gate by finding that port. A native local
process could, but such a process can reach the ROS graph directly anyway.

The gate is a small process of its own (FoxgloveGate starts and stops it; only the standard
library runs there); `on_refused(text)` is called from a thread that reads its reports.
"""
from __future__ import annotations

import asyncio
import datetime
import ipaddress
import json
import re
import signal
import socket
import ssl
import subprocess
import sys
import threading
import time
from typing import Callable, Iterable

SDK_SUBPROTOCOL = "foxglove.sdk.v1"
SUBPROTOCOLS = (SDK_SUBPROTOCOL, "foxglove.websocket.v1")
FOXGLOVE_APP_ORIGIN = "https://app.foxglove.dev"
# file://: the desktop apps (Electron) load their pages from files; no web page has that Origin.
BUILT_IN_ORIGINS = (FOXGLOVE_APP_ORIGIN, "file://")
_LOOPBACK_ORIGIN = re.compile(r"https?://(localhost|127\.0\.0\.1|\[::1\])(:\d{1,5})?")
_ORIGIN_FORM = re.compile(r"[a-z][a-z0-9+.-]*://[^/?#\s]*")
_MAX_REQUEST_BYTES = 16 * 1024
_HANDSHAKE_TIMEOUT_S = 10.0
_RELAY_CHUNK = 256 * 1024


def _canonical(origin: str) -> str:
    text = origin.strip().lower()
    return text if text == "file://" else text.rstrip("/")


def normalize_origin(origin: str) -> str:
    """An Origin as compared: lower case, without a trailing slash.

    ValueError unless it is scheme://host[:port] (no path), e.g. https://lichtblick.example.org.
    """
    text = _canonical(origin)
    if not _ORIGIN_FORM.fullmatch(text):
        raise ValueError(f"'{origin}' is not an origin like https://host[:port] (no path)")
    return text


def origin_allowed(origin: str | None, extra: Iterable[str] = ()) -> bool:
    """Whether a handshake with this Origin header (None: no header) may open the bridge.

    Allowed: no Origin (native clients: scripts, the ROS tools, desktop apps that send none),
    the Foxglove web app, file:// (desktop apps), pages served by this machine
    (http(s)://localhost, 127.0.0.1 or [::1], any port: a self-hosted Lichtblick or Foxglove)
    and `extra` (normalized origins). Never "null": a sandboxed frame of any page sends it.
    """
    if origin is None:
        return True
    text = _canonical(origin)
    return (text in BUILT_IN_ORIGINS or text in extra
            or _LOOPBACK_ORIGIN.fullmatch(text) is not None)


def self_signed_certificate() -> tuple[bytes, bytes]:
    """(certificate, PKCS#8 key), PEM, for the SDK's loopback TLS port; made per start."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "amr foxglove bridge (loopback)")])
    now = datetime.datetime.now(datetime.timezone.utc)
    certificate = (
        x509.CertificateBuilder().subject_name(name).issuer_name(name)
        .public_key(key.public_key()).serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(hours=1))
        .not_valid_after(now + datetime.timedelta(days=3650))
        .add_extension(x509.SubjectAlternativeName(
            [x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
        .sign(key, hashes.SHA256()))
    return (certificate.public_bytes(serialization.Encoding.PEM),
            key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                              serialization.NoEncryption()))


class HandshakeRefused(Exception):
    """A handshake the gate answers itself: `status` is the HTTP status line's tail."""

    def __init__(self, status: str, text: str) -> None:
        super().__init__(text)
        self.status = status


def check_request(head: bytes, extra_origins: Iterable[str]) -> tuple[str, bytes]:
    """(the subprotocol to answer with, the request to send the SDK) of an upgrade request.

    HandshakeRefused("403 Forbidden" / "400 Bad Request", why) if it may not pass.
    """
    lines = head.decode("latin-1").split("\r\n")
    headers = [line.split(":", 1) for line in lines[1:] if ":" in line]
    origins = [value.strip() for name, value in headers if name.strip().lower() == "origin"]
    if len(origins) > 1 or not origin_allowed(origins[0] if origins else None, extra_origins):
        raise HandshakeRefused("403 Forbidden", f"Origin {', '.join(origins)[:100]!r} is not "
                               "allowed (add it with --foxglove-origin / allowed_origins)")
    offered = [p.strip() for name, value in headers
               if name.strip().lower() == "sec-websocket-protocol" for p in value.split(",")]
    chosen = next((p for p in offered if p in SUBPROTOCOLS), None)
    if chosen is None:
        raise HandshakeRefused("400 Bad Request", f"expected Sec-WebSocket-Protocol "
                               f"{' or '.join(SUBPROTOCOLS)} (got {', '.join(offered)[:100]!r})")
    kept = [line for line in lines[1:]
            if line and not line.lower().startswith("sec-websocket-protocol:")]
    request = "\r\n".join([lines[0], *kept, f"Sec-WebSocket-Protocol: {SDK_SUBPROTOCOL}", "", ""])
    return chosen, request.encode("latin-1")


def rewrite_response(head: bytes, chosen: str) -> bytes:
    """The SDK's handshake response with the subprotocol the client offered."""
    lines = head.decode("latin-1").split("\r\n")
    return "\r\n".join(f"Sec-WebSocket-Protocol: {chosen}"
                       if line.lower().startswith("sec-websocket-protocol:") else line
                       for line in lines).encode("latin-1")


class FoxgloveGate:
    """The gate, in a process of its own, on host:port in front of the SDK's loopback TLS port.

    A process of its own: relaying costs the ROS process no interpreter time (in-process, the
    relay slowed a lockstep simulation with a client attached by about a third). It exits when
    stop() closes its stdin, or when this process ends (its stdin closes too); Ctrl-C in the
    terminal does not reach it (a session of its own): the node decides when it stops.
    """

    def __init__(self, host: str, port: int, sdk_port: int, sdk_certificate: bytes,
                 extra_origins: Iterable[str] = (),
                 on_refused: Callable[[str], None] | None = None) -> None:
        self._config = {"host": host, "port": port, "sdk_port": sdk_port,
                        "certificate": sdk_certificate.decode("ascii"),
                        "origins": sorted(extra_origins)}
        self._on_refused = on_refused or (lambda text: None)
        self._process: subprocess.Popen | None = None
        self.port = port

    def start(self, timeout: float = 10.0) -> None:
        """Start the process and wait until it listens; OSError (its reason) if it cannot."""
        self._process = subprocess.Popen(
            [sys.executable, __file__], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            text=True, start_new_session=True)
        self._process.stdin.write(json.dumps(self._config) + "\n")
        self._process.stdin.flush()
        first: list[str] = []
        reader = threading.Thread(target=self._read_reports, args=(first,), daemon=True,
                                  name="foxglove-gate-reports")
        reader.start()
        deadline = time.monotonic() + timeout
        while not first and reader.is_alive() and time.monotonic() < deadline:
            time.sleep(0.01)
        report = json.loads(first[0]) if first else {"error": "the gate did not start"}
        if "port" not in report:
            self.stop()
            raise OSError(report.get("error", "the gate did not start"))
        self.port = report["port"]

    def _read_reports(self, first: list[str]) -> None:
        for line in self._process.stdout:
            if not first:
                first.append(line)
                continue
            try:
                self._on_refused(json.loads(line)["refused"])
            except (ValueError, KeyError, TypeError):
                pass

    def stop(self) -> None:
        """Close the listener and every relayed connection; returns when the process ended."""
        if self._process is None:
            return
        process, self._process = self._process, None
        try:
            process.stdin.close()
            process.wait(timeout=5.0)
        except (OSError, subprocess.TimeoutExpired):
            process.kill()
            process.wait()


async def serve(config: dict, report: Callable[[dict], None], stop: asyncio.Event) -> None:
    """Listen on config's host:port until `stop` is set; report({"port": N}) once listening."""
    tls = ssl.create_default_context(cadata=config["certificate"])
    tls.check_hostname = False  # the pinned certificate is the only one trusted
    extra = frozenset(config["origins"])
    connections: set[asyncio.Task] = set()

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        connections.add(asyncio.current_task())
        upstream = None
        try:
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), _HANDSHAKE_TIMEOUT_S)
            try:
                chosen, request = check_request(head, extra)
            except HandshakeRefused as refused:
                report({"refused": f"refused a WebSocket handshake: {refused}"})
                body = f"{refused}\n".encode()
                writer.write(f"HTTP/1.1 {refused.status}\r\nContent-Type: text/plain\r\n"
                             f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n"
                             .encode() + body)
                await writer.drain()
                return
            sdk_reader, upstream = await asyncio.open_connection(
                "127.0.0.1", config["sdk_port"], ssl=tls, limit=_MAX_REQUEST_BYTES)
            upstream.write(request)
            response = await asyncio.wait_for(sdk_reader.readuntil(b"\r\n\r\n"),
                                              _HANDSHAKE_TIMEOUT_S)
            writer.write(rewrite_response(response, chosen))
            await _relay_both_ways(reader, writer, sdk_reader, upstream)
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, asyncio.TimeoutError,
                ConnectionError, ssl.SSLError, OSError):
            pass  # a client that left or sent no request: nothing to answer
        finally:
            for stream in (writer, upstream):
                if stream is not None:
                    stream.close()
            connections.discard(asyncio.current_task())

    try:
        listener = _bind(config["host"], config["port"])
    except OSError as exc:
        report({"error": str(exc)})
        return
    server = await asyncio.start_server(handle, sock=listener, limit=_MAX_REQUEST_BYTES)
    report({"port": listener.getsockname()[1]})
    await stop.wait()
    server.close()
    for task in list(connections):
        task.cancel()
    await asyncio.gather(*connections, return_exceptions=True)


async def _relay_both_ways(client_reader, client_writer, sdk_reader, sdk_writer) -> None:
    """Copy bytes both ways until either side closes; then the other is closed too."""
    async def pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        while data := await reader.read(_RELAY_CHUNK):
            writer.write(data)
            await writer.drain()  # backpressure: a slow client slows the SDK's sends to it

    pipes = [asyncio.ensure_future(pipe(client_reader, sdk_writer)),
             asyncio.ensure_future(pipe(sdk_reader, client_writer))]
    try:
        await asyncio.wait(pipes, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in pipes:
            task.cancel()
        await asyncio.gather(*pipes, return_exceptions=True)


def _bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on the first address of host (one port even for port 0)."""
    family, kind, proto, _, address = socket.getaddrinfo(
        host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)[0]
    listener = socket.socket(family, kind, proto)
    try:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(address)
        listener.listen(128)
    except OSError:
        listener.close()
        raise
    listener.setblocking(False)
    return listener


def main() -> int:
    """The gate's process: a JSON config line on stdin, JSON reports on stdout, ends at EOF."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    config = json.loads(sys.stdin.readline())

    def report(message: dict) -> None:
        print(json.dumps(message), flush=True)

    async def run() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()

        def wait_for_eof() -> None:
            sys.stdin.read()  # returns when the node closes our stdin or ends
            loop.call_soon_threadsafe(stop.set)

        threading.Thread(target=wait_for_eof, daemon=True).start()
        await serve(config, report, stop)

    asyncio.run(run())
    return 0


if __name__ == "__main__":
    sys.exit(main())
