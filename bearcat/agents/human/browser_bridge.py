"""The bridge between a phone's browser and the bus: an HTTPS server with a WebSocket.

A phone's browser gives a page its position only in a secure context, so
the bridge serves HTTPS: with the certificate the user gives, or one it
makes for the session (the phone then asks once whether to trust it). The
page's link carries a per-player token; a request without it gets nothing,
so the person next to you cannot open your page or speak for you. What the
page sends goes to the ``PagePhone`` agent (which checks every fix as any
fix is checked); four times a second every open page gets the screen.

Everything here runs on the peer's asyncio loop, beside the live runtime
driving the agent.
"""

from __future__ import annotations

import asyncio
import datetime
import hmac
import json
import logging
import secrets
import ssl
import tempfile
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from aiohttp import WSMsgType, web

from bearcat.agents.human.page_phone import PagePhone
from bearcat.bus.addresses import local_addresses, reachable
from bearcat.bus.endpoints import WILDCARDS
from bearcat.bus.errors import BusError
from bearcat.bus.identity import self_signed

log = logging.getLogger(__name__)

REFRESH = 0.25  # s between the screens sent to each open page
MAX_MESSAGE = 4096  # bytes: a fix is about a hundred
SESSION = datetime.timedelta(days=2)  # how long the page's own certificate holds


@dataclass(frozen=True)
class PageServer:
    """Where the bridge listens and how a page proves it is the player's:
    ``token`` in its link; ``cert``/``key`` the HTTPS certificate (None:
    one made for the session, naming ``host``)."""

    host: str = "0.0.0.0"
    port: int = 8443
    token: str = ""
    cert: Path | None = None
    key: Path | None = None

    def url(self, address: str | None = None) -> str:
        """The page's link, naming ``address`` (default: where a phone on the same network reaches ``host``)."""
        return f"https://{address or reachable(self.host)}:{self.port}/?token={self.token}"

    def qr(self, address: str | None = None) -> str:
        """The link as a QR code for a terminal, to point the phone's camera at."""
        import io

        import segno

        out = io.StringIO()
        segno.make(self.url(address), error="l").terminal(out=out, compact=True)
        return out.getvalue()


def new_token() -> str:
    return secrets.token_urlsafe(16)


PAGE = "0.0.0.0:8443"
"""Where a phone's page is served unless told otherwise: every interface, HTTPS's alternative port."""


def page_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` as a host and a port; one sentence for anything else."""
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise BusError(f"{text!r} is not HOST:PORT, e.g. {PAGE}")
    return host, int(port)


def page_server(page: str | None, cert: str | Path | None, key: str | Path | None, token_file: str | Path | None):
    """The server of a phone's page at ``page`` (HOST:PORT, None: ``PAGE``)
    with ``cert`` and ``key`` (both or neither: neither makes one for the
    session) and the token kept in ``token_file`` (None: a new one)."""
    if (cert is None) != (key is None):
        raise BusError("--cert and --key go together: the page's certificate and its key")
    token = Path(token_file).read_text().strip() if token_file else new_token()
    host, port = page_address(page or PAGE)
    return PageServer(
        host=host,
        port=port,
        token=token,
        cert=None if cert is None else Path(cert),
        key=None if key is None else Path(key),
    )


class Bridge:
    """Serves ``page`` (the agent) to browsers as ``server`` says; ``now()`` is the peer's clock."""

    def __init__(self, page: PagePhone, server: PageServer, now, *, on_drop=None) -> None:
        self.page = page
        self.server = server
        self.now = now
        self.on_drop = on_drop or (lambda reason: None)
        self.first_fix = asyncio.Event()
        self.sockets: set[web.WebSocketResponse] = set()
        self._runner: web.AppRunner | None = None
        self._pusher: asyncio.Task | None = None
        self._index = resources.files("bearcat.agents.human").joinpath("page/index.html").read_bytes()

    async def start(self) -> None:
        app = web.Application(client_max_size=MAX_MESSAGE)
        app.add_routes(
            [
                web.get("/", self._index_page),
                web.get("/ws", self._socket),
                web.get("/favicon.ico", self._no_icon),
            ]
        )
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.server.host, self.server.port, ssl_context=self._tls())
        await site.start()
        self._pusher = asyncio.create_task(self._push())

    async def close(self) -> None:
        if self._pusher is not None:
            self._pusher.cancel()
            await asyncio.gather(self._pusher, return_exceptions=True)
        for ws in list(self.sockets):
            await ws.close()
        if self._runner is not None:
            await self._runner.cleanup()

    def _allowed(self, request: web.Request) -> bool:
        given = request.query.get("token", "")
        return bool(self.server.token) and hmac.compare_digest(given.encode(), self.server.token.encode())

    async def _index_page(self, request: web.Request) -> web.Response:
        if not self._allowed(request):
            return web.Response(status=403, text="This link lacks its player's token: open the link you were given.")
        return web.Response(body=self._index, content_type="text/html", headers={"Cache-Control": "no-store"})

    async def _no_icon(self, request: web.Request) -> web.Response:
        return web.Response(status=204)

    async def _socket(self, request: web.Request) -> web.StreamResponse:
        if not self._allowed(request):
            return web.Response(status=403, text="no token")
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=MAX_MESSAGE)
        await ws.prepare(request)
        self.sockets.add(ws)
        try:
            await ws.send_json({"type": "map", "map": self.page.map_view()})
            await ws.send_json({"type": "view", "view": self.page.view(self.now())})
            async for message in ws:
                if message.type == WSMsgType.TEXT:
                    self._received(message.data)
        finally:
            self.sockets.discard(ws)
        return ws

    def _received(self, text: str) -> None:
        try:
            data = json.loads(text)
        except ValueError:
            data = None
        if not isinstance(data, dict) or data.pop("type", None) != "fix":
            self.page.drops["not a fix"] += 1
            self.on_drop("the page sent something that is not a fix")
            return
        why = self.page.report(data, self.now())
        if why is None:
            self.first_fix.set()
        else:
            self.on_drop(why)

    async def _push(self) -> None:
        while True:
            await asyncio.sleep(REFRESH)
            if not self.sockets:
                continue
            text = json.dumps({"type": "view", "view": self.page.view(self.now())})
            for ws in list(self.sockets):
                try:
                    await ws.send_str(text)
                except (ConnectionError, RuntimeError):
                    self.sockets.discard(ws)

    def _tls(self) -> ssl.SSLContext:
        context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        if self.server.cert is not None:
            context.load_cert_chain(self.server.cert, self.server.key)
            return context
        with tempfile.TemporaryDirectory(prefix="bearcat-page-") as held:
            # The phone asks once whether to trust it.
            names = local_addresses() if self.server.host in (*WILDCARDS, "") else (self.server.host,)
            cert, key = self_signed(Path(held), "page", "bearcat phone", names, SESSION)
            context.load_cert_chain(cert, key)
        return context
