"""The recording's HTTP server of ``slam view --web``: one file, on 127.0.0.1, for the web viewer.

``rerun --serve-web FILE.rrd`` loads the file into a gRPC server of its own, and that server
keeps a core busy while it idles (rerun 0.2x: its receive loop yields instead of waiting;
upstream rerun-io/rerun#10944). Given an ``http://`` URL instead, the web viewer fetches the
recording itself and no gRPC server is started, so ``slam view --web`` serves the file here and
passes its URL. :class:`RecordingServer` answers ``GET``/``HEAD`` of that one path (anything else
is 404), in a daemon thread, on 127.0.0.1 only; a request from one of the web viewer's own pages
(``Origin`` ``http://127.0.0.1:PORT`` or ``http://localhost:PORT``) gets the CORS header that
lets the page read the answer, other origins get none; a request whose ``Host`` is not
``127.0.0.1:PORT`` or ``localhost:PORT`` is refused (403), so that a page that made another name
resolve to 127.0.0.1 (DNS rebinding) cannot read the recording either.
"""

from __future__ import annotations

import threading
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import BinaryIO
from urllib.parse import quote

from slam.viz.stream import LOOPBACK

CHUNK_BYTES = 1 << 20
"""The file is sent in pieces of this size."""


class RecordingServer:
    """Serve ``recording`` at ``http://127.0.0.1:PORT/<name>`` until :meth:`close` (or the end of
    a ``with`` block); ``viewer_port`` is the web viewer's HTTP port, whose pages may read it."""

    def __init__(self, recording: Path, viewer_port: int, port: int = 0) -> None:
        self.recording = Path(recording)
        self.name = self.recording.name
        origins = {f"http://{host}:{viewer_port}" for host in (LOOPBACK, "localhost")}
        handler = _handler(self.recording, "/" + quote(self.name), frozenset(origins))
        self._server = ThreadingHTTPServer((LOOPBACK, port), handler)
        self._server.daemon_threads = True
        self.port = int(self._server.server_address[1])
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        """Where the recording is served."""
        return f"http://{LOOPBACK}:{self.port}/{quote(self.name)}"

    def close(self) -> None:
        """Stop serving and release the port."""
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(timeout=5)

    def __enter__(self) -> RecordingServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _handler(recording: Path, path: str, origins: frozenset[str]) -> type[BaseHTTPRequestHandler]:
    """The request handler class serving ``recording`` at ``path`` (see the module docstring)."""

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self._answer(body=True)

        def do_HEAD(self) -> None:
            self._answer(body=False)

        def _answer(self, body: bool) -> None:
            port = self.server.server_address[1]
            if self.headers.get("Host") not in (f"{LOOPBACK}:{port}", f"localhost:{port}"):
                self.send_error(HTTPStatus.FORBIDDEN)  # another name for 127.0.0.1: rebinding
                return
            if self.path.split("?", 1)[0] != path:
                self.send_error(HTTPStatus.NOT_FOUND)
                return
            try:
                f = open(recording, "rb")  # noqa: SIM115 (closed below; only opening is a 404)
            except OSError:
                self.send_error(HTTPStatus.NOT_FOUND)
                return
            with f:
                self._send(f, body)

        def _send(self, f: BinaryIO, body: bool) -> None:
            size = f.seek(0, 2)
            f.seek(0)
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", "application/octet-stream")
            self.send_header("Content-Length", str(size))
            self.send_header("Cache-Control", "no-store")
            origin = self.headers.get("Origin")
            if origin in origins:
                self.send_header("Access-Control-Allow-Origin", origin)
                self.send_header("Vary", "Origin")
            self.end_headers()
            try:
                while body and (chunk := f.read(CHUNK_BYTES)):
                    self.wfile.write(chunk)
            except (BrokenPipeError, ConnectionResetError):
                pass  # the page was closed or reloaded mid-file

        def log_message(self, format: str, *args: object) -> None:
            pass  # the viewer's requests are not the user's business

    return Handler
