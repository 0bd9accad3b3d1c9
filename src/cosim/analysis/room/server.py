"""The decision room's web server: a Bokeh server app serving one study at ``http://HOST:PORT/``.

- Bound to loopback (127.0.0.1) by default: only this machine reaches it.
- A token on every address, loopback included (a login node is shared by many users; Jupyter's convention):
  the printed link carries ``?token=...`` (random, 32 bytes); the page opened with it sets a cookie
  (HttpOnly, SameSite=Strict) that the page's websocket then carries.  A request without either is refused
  with 403.  ``no_token=True`` (``cosim explore --no-token``) serves without one; the websocket then accepts
  pages of this server's own address only (bokeh's origin check).
- Every page is sent with a Content-Security-Policy that lets only bokeh's own scripts run (:mod:`.policy`).
- Port 0 (the default) takes a free port; the link says which.

A results folder is served as a :class:`.live.LiveStudy`: the page draws new rows as a running study writes
them.  :func:`serve` runs until Ctrl-C; :class:`RoomServer` runs the same server in a thread (tests, notebooks).
"""

from __future__ import annotations

import asyncio
import errno
import hashlib
import hmac
import ipaddress
import logging
import secrets
import socket
import threading
from collections.abc import Callable
from functools import partial
from typing import Any

from cosim.analysis.room.data import Study
from cosim.analysis.room.live import LiveStudy
from cosim.analysis.table import AnalysisError

TOKEN_COOKIE = "cosim_room_token"  # + "_" and 12 hex digits of the token's hash: cookie_name(token)
LOOPBACK = "127.0.0.1"


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address or a name) is this machine's loopback only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def cookie_name(token: str) -> str:
    """The cookie of one room's token: a browser sends a cookie of 127.0.0.1 to every port of it, so two rooms
    open at once (two studies, two users) each keep their own (Jupyter names its cookie by port likewise)."""
    return f"{TOKEN_COOKIE}_{hashlib.sha256(token.encode()).hexdigest()[:12]}"


def link_host(host: str) -> str:
    """The host to print in the link: the machine's name for a wildcard address, else ``host``."""
    return socket.gethostname() if host in ("0.0.0.0", "::", "") else host


def token_auth(token: str) -> Any:
    """A bokeh AuthProvider admitting requests with ``?token=TOKEN`` or the cookie that a page opened with it set.

    The cookie (HttpOnly, SameSite=Strict) is set on the page's HTTP response only: a websocket has no headers
    to set (tornado raises, and the page stayed blank: issue 38.2).  A request without either is refused before
    anything else happens: a page is sent to ``/denied`` (403 and one sentence), a websocket gets a plain 403
    (tornado's access log prints one line for it, never a traceback)."""
    from bokeh.server.auth_provider import AuthProvider
    from tornado.web import HTTPError, RequestHandler
    from tornado.websocket import WebSocketHandler

    class Denied(RequestHandler):
        def get(self) -> None:
            self.set_status(403)
            self.write("cosim explore: this page needs the link with its token, as cosim printed it.\n")

    cookie_key = cookie_name(token)

    async def get_user(handler: Any) -> str | None:
        websocket = isinstance(handler, WebSocketHandler)
        given = handler.get_argument("token", default=None)
        if given is not None and hmac.compare_digest(given, token):
            if not websocket:
                handler.set_cookie(cookie_key, token, httponly=True, samesite="Strict")
            return "cosim"
        cookie = handler.get_cookie(cookie_key)
        if cookie is not None and hmac.compare_digest(cookie, token):
            return "cosim"
        if websocket:  # bokeh's @authenticated would redirect, which a websocket cannot: a traceback per attempt
            raise HTTPError(403)
        return None

    class TokenAuth(AuthProvider):
        @property
        def get_user_async(self) -> Callable[[Any], Any]:
            return get_user

        @property
        def login_url(self) -> str:
            return "/denied"

        @property
        def login_handler(self) -> type:
            return Denied

    return TokenAuth()


def free_port(host: str) -> int:
    """A port free on ``host`` now (the server binds it just after; a lost race is retried)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


class _NotForTheUser(logging.Filter):
    """Drops bokeh's note that a tab closed before a message to it went out: the user closed it."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.getMessage() != "Failed sending message as connection was closed"


class _NotNewsWithAToken(logging.Filter):
    """Drops bokeh's warning that origin '*' admits every site: with a token the websocket must carry the
    token (or its cookie, SameSite=Strict, which another site's page never sends), whatever the origin."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith("Host wildcard '*' will allow connections")


_QUIET = _NotForTheUser()
_WILDCARD = _NotNewsWithAToken()


def quiet_room_logs() -> None:
    """Keep bokeh's notes that are no news to the user off the terminal of ``cosim explore``.

    - ``W-1002 (EMPTY_LAYOUT)``: the tabs of the room are built when first shown (issue 27), so each new page
      has empty layouts on purpose; bokeh warned four times per page opened.
    - ``Failed sending message as connection was closed``: a tab was closed while the server sent to it.
    - ``BokehUserWarning: reference already known '...'``: printed at every click of *Re-run selected*.  The
      page sends the button whole (its attributes, not only its id) with the click event (the button came
      with its tab, after the page loaded); bokeh's server, which knows the button, keeps its own model and
      warns (a warning, not an error, since bokeh/bokeh#12915).  Nothing is lost.
    Idempotent; real problems (errors, other warnings) are still printed.
    """
    import warnings

    from bokeh.core.validation import silence
    from bokeh.core.validation.warnings import EMPTY_LAYOUT
    from bokeh.util.warnings import BokehUserWarning

    silence(EMPTY_LAYOUT, True)
    warnings.filterwarnings("ignore", message="reference already known ", category=BokehUserWarning)
    ws = logging.getLogger("bokeh.server.views.ws")
    if _QUIET not in ws.filters:
        ws.addFilter(_QUIET)
    util = logging.getLogger("bokeh.server.util")
    if _WILDCARD not in util.filters:
        util.addFilter(_WILDCARD)


def serve_without_mathjax(server: Any) -> None:
    """Leave bokeh's MathJax bundle out of the pages ``server`` (a bokeh Server) serves.

    bokeh's server page loads every bundle, not knowing what the page will hold: MathJax is 1.8 MB of the
    3.9 MB of JavaScript, parsed at each load, for TeX the room never typesets (its texts are plain; the
    labels are column names).  bokeh has no option for it (bokeh/embed/server.py asks for every component
    when it makes the page), so the server's resources are replaced by the same without that component.
    """
    tornado = server._tornado  # bokeh 3.4 to 3.9: the BokehTornado whose resources() the page handler asks
    resources = tornado.resources

    def lighter(absolute_url: Any = None) -> Any:
        full = resources(absolute_url)
        return full.clone(components=[c for c in full.components if c != "bokeh-mathjax"])

    tornado.resources = lighter


def make_server(study: Study | LiveStudy, host: str = LOOPBACK, port: int = 0, token: str | None = None,
                webgl: bool | None = None, io_loop: Any = None, aggregate_above: int | None = None,
                no_token: bool = False) -> tuple[Any, str]:
    """(a started-to-be bokeh Server of the room on ``host:port``, its link).  A token is made when none is
    given, on every host (``no_token`` serves without one); ``webgl`` None lets the room choose by the table's
    size, and ``aggregate_above`` (rows) overrides the size from which the cloud is an image of bins.  Raises
    AnalysisError when the address cannot be bound."""
    from bokeh.application import Application
    from bokeh.application.handlers.function import FunctionHandler
    from bokeh.server.server import Server

    from cosim.analysis.room.app import make_document
    from cosim.analysis.room.policy import script_policy

    if no_token:
        token = None
    elif token is None:
        token = secrets.token_urlsafe(32)
    quiet_room_logs()
    application = Application(FunctionHandler(partial(make_document, study=study, webgl=webgl,
                                                         aggregate_above=aggregate_above)))
    options: dict[str, Any] = {"address": host, "websocket_max_message_size": 512 * 1024 * 1024}
    if io_loop is not None:
        options["io_loop"] = io_loop
    if token:
        # any origin: the page's websocket must carry the token's cookie, which is SameSite=Strict
        options.update(auth_provider=token_auth(token), allow_websocket_origin=["*"])
    for attempt in range(5):
        chosen = port
        try:
            chosen = port or free_port(host)
            if not token:  # bokeh's default origin list names localhost only
                options["allow_websocket_origin"] = [f"{h}:{chosen}" for h in dict.fromkeys(
                    ("127.0.0.1", "localhost", host))]
            server = Server({"/": application}, port=chosen, **options)
            break
        except OSError as exc:
            if port == 0 and exc.errno == errno.EADDRINUSE and attempt < 4:
                continue  # another program took the free port meanwhile
            raise AnalysisError(f"cosim explore: cannot serve at {host}:{chosen}: {exc.strerror or exc}; choose "
                                "another --port (0 takes a free one)") from None
    serve_without_mathjax(server)
    server._tornado.add_transform(script_policy())
    link = f"http://{link_host(host)}:{server.port}/" + (f"?token={token}" if token else "")
    return server, link


def serve(study: Study | LiveStudy, host: str = LOOPBACK, port: int = 0, token: str | None = None,
          announce: Callable[[str], None] = print, no_token: bool = False) -> None:
    """Serve the room until interrupted, announcing its link first.

    Runs until KeyboardInterrupt (Ctrl-C; under the ``cosim`` command also SIGTERM and SIGHUP, which
    :func:`cosim.parallel.cluster.interrupts.stop_cleanly_on_signals` turns into it): the server then closes its
    sockets and the KeyboardInterrupt is raised again, so the command ends as every interrupted command does
    (``cosim: interrupted``, exit 130).  Open pages and a re-run in progress (a daemon thread) do not hold it.
    """
    server, link = make_server(study, host, port, token, no_token=no_token)
    server.start()
    announce(f"cosim explore: the decision room of {study.name} is at {link}  (Ctrl-C stops it)")
    if no_token:
        where = "every user of this machine" if is_loopback(host) else "everyone who reaches this address"
        announce(f"cosim explore: warning: --no-token: {where} can read this study and re-run its designs")
    try:
        server.io_loop.start()
    finally:
        server.stop()


class RoomServer:
    """The room served from a daemon thread with its own event loop: ``link``, ``stop()``."""

    def __init__(self, study: Study | LiveStudy, host: str = LOOPBACK, port: int = 0, token: str | None = None,
                 webgl: bool | None = None, aggregate_above: int | None = None, no_token: bool = False):
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.link = ""
        self.thread = threading.Thread(target=self._run, args=(study, host, port, token, webgl, aggregate_above,
                                                                  no_token),
                                       daemon=True, name="cosim-room-server")
        self.thread.start()
        self._ready.wait(60)
        if self._error is not None:
            raise self._error

    def _run(self, study: Study | LiveStudy, host: str, port: int, token: str | None, webgl: bool | None,
             aggregate_above: int | None, no_token: bool) -> None:
        from tornado.ioloop import IOLoop

        asyncio.set_event_loop(asyncio.new_event_loop())
        try:
            self.server, self.link = make_server(study, host, port, token, webgl, io_loop=IOLoop.current(),
                                                    aggregate_above=aggregate_above, no_token=no_token)
            self.server.start()
        except BaseException as exc:
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        self.server.io_loop.start()

    def stop(self) -> None:
        loop = self.server.io_loop

        def stop_here() -> None:
            self.server.stop()
            loop.stop()

        loop.add_callback(stop_here)
        self.thread.join(10)
