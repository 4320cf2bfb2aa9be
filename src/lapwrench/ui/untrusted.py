"""The page's server and its untrusted clients: what viser does with a client's garbage, told in one line.

Anyone who can reach the page's port can send the server anything: a text frame, bytes that are not
msgpack, msgpack that is not a viser message, a message of an unknown type, fields of the wrong type
(a slider set to ``"abc"``, a property the element does not have). viser refuses such a message by
raising on its own event loop, in one of two places of its receive path:

- decoding (``_message_consumer``): the connection handler fails, viser closes that connection, and
  websockets logs ``connection handler failed`` with the traceback;
- dispatching a decoded message to its handlers (``_handle_incoming_message``, a task per message):
  the task fails and asyncio logs ``Task exception was never retrieved`` with the traceback.

A connection that is not a WebSocket handshake at all (junk instead of HTTP, a bad upgrade request)
is refused by websockets, which logs ``opening handshake failed`` with the traceback (viser hides
that message, but only from its first HTTP request on).

:class:`UntrustedClients` turns each into one line of an :class:`~lapwrench.hardware.log.live.IncidentLog`
(``lapwrench ui: closed the connection of 127.0.0.1:53412 after a malformed message: DecodeError: ...``,
rate-limited), through the hooks the libraries offer: a :class:`logging.Filter` on websockets' server
logger (its records carry the connection, hence the client's address) and an exception handler on
viser's event loop (:meth:`viser.ViserServer.get_event_loop`). viser's warning about a tuple of the
wrong length in a client's message is not shown (a warnings filter): the message is refused or
applied as it is, and a refusal has its line.

A client can also ask viser to share the page: a ``ShareUrlRequest`` (a button of viser's page,
and any program that reaches the port, a web page in the user's browser included: browsers let any
site open a WebSocket to localhost) makes viser open a public tunnel through share.viser.studio, so
that anyone on the internet can reach the page. lapwrench never shares its page: :class:`PageServer`
refuses the request with one line.

Only refused handshakes and failures of that receive path are told this way (a client that hangs up
mid-handshake is not told at all), and a failure only when no frame of lapwrench's own code is in its
traceback: anything else (a bug of ours in a callback, a failure while sending) is left to the
libraries and shows its full traceback, as before.
"""

from __future__ import annotations

import asyncio
import logging
import traceback
import warnings
from pathlib import Path
from types import FrameType
from typing import Any

import viser

import lapwrench
from lapwrench.hardware.log.live import IncidentLog

WHO = "lapwrench ui"
WEBSOCKETS_LOGGER = "websockets.server"  # websockets' server logger, the one viser's server uses
VISER_INFRA = "viser.infra._infra"  # the module of viser's receive path...
DECODE = "_message_consumer"  # ...its coroutine that reads and decodes each client message,
DISPATCH = "_handle_incoming_message"  # ...and the one that hands a decoded message to its handlers
ANNOTATION_WARNING = r"\[viser\] .* does not match annotation"  # viser decoding a tuple of the wrong length
PACKAGE = Path(lapwrench.__file__).resolve().parent


def receive_failure(exc: BaseException) -> tuple[str, dict[str, Any]] | None:
    """Where viser's receive path failed on a client's message, when that is what ``exc`` is: the
    function (:data:`DECODE` or :data:`DISPATCH`) and its variables; None when no frame of the
    traceback is one of them, or when one is lapwrench's own code (a genuine error: shown in full)."""
    found: tuple[str, dict[str, Any]] | None = None
    for frame, _ in traceback.walk_tb(exc.__traceback__):
        if Path(frame.f_code.co_filename).resolve().is_relative_to(PACKAGE):
            return None
        if is_receive_frame(frame) and found is None:
            found = (frame.f_code.co_name, dict(frame.f_locals))
    return found


def is_receive_frame(frame: FrameType) -> bool:
    """A frame of viser's receive path (:data:`DECODE`, :data:`DISPATCH`)."""
    return frame.f_globals.get("__name__") == VISER_INFRA and frame.f_code.co_name in (DECODE, DISPATCH)


def exception_text(exc: BaseException) -> str:
    """``Type: message`` (or the type alone when the exception says nothing)."""
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def peer_of(connection: object) -> str:
    """``host:port`` of a websockets connection's client (``a client`` when it cannot be told)."""
    address = getattr(connection, "remote_address", None)
    if isinstance(address, tuple) and len(address) >= 2:
        return f"{address[0]}:{address[1]}"
    return "a client"


def incident(where: str, variables: dict[str, Any], exc: BaseException, peer: str | None) -> str:
    """The line for a message viser refused at ``where`` (its frame's ``variables``)."""
    if where == DECODE:
        raw = variables.get("raw")
        reason = "a text frame (viser's clients send binary msgpack)" if isinstance(raw, str) else exception_text(exc)
        return f"closed the connection of {peer or 'a client'} after a malformed message: {reason}"
    message = variables.get("message")
    kind = f"{type(message).__name__}: " if message is not None else ""
    client = variables.get("client_id")
    sender = peer or (f"page client {client}" if isinstance(client, int) else "a page client")
    return f"ignored a malformed message from {sender}: {kind}{exception_text(exc)}"


def refused_handshake(exc: BaseException) -> bool:
    """``exc`` is websockets refusing a client's opening handshake (not HTTP, a bad upgrade request),
    not a failure of the server's own code while answering it."""
    from websockets.exceptions import InvalidHandshake

    return isinstance(exc, InvalidHandshake)


def hung_up(exc: BaseException) -> bool:
    """The client closed the connection: ``exc`` or its causes are an end of file or a reset (a
    browser's speculative connection does that, and a client that goes away mid-request)."""
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, EOFError | ConnectionError):
            return True
        seen = seen.__cause__
    return False


class ClientFailures(logging.Filter):
    """On websockets' server logger: a record whose exception a client caused becomes one incident line
    (or nothing, for a client that hung up during its handshake) and is dropped; any other passes.

    A client caused: a failure of viser's receive path (:func:`receive_failure`; ``connection handler
    failed``) and a refused opening handshake (``opening handshake failed``, which viser's own filter
    hides only after its first HTTP request: the first connection of garbage printed a traceback).
    """

    def __init__(self, incidents: IncidentLog) -> None:
        super().__init__()
        self.incidents = incidents

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        if exc is None:
            return True
        peer = peer_of(getattr(record, "websocket", None))
        if refused_handshake(exc):
            if not hung_up(exc):
                cause = f" ({exception_text(exc.__cause__)})" if exc.__cause__ is not None else ""
                self.incidents.report(f"refused a connection from {peer}: {exc}{cause}")
            return False
        failure = receive_failure(exc)
        if failure is None:
            return True
        self.incidents.report(incident(*failure, exc, peer))
        return False


class PageServer(viser.ViserServer):
    """viser's server for lapwrench's page, which it never shares on the internet: a client's
    ``ShareUrlRequest`` (module docstring) is refused, one line in :attr:`incidents` (set by
    :class:`UntrustedClients`), and no tunnel is opened."""

    incidents: IncidentLog | None = None

    def request_share_url(self, verbose: bool = True) -> str | None:
        if self.incidents is not None:
            self.incidents.report("refused a request to share the page on the internet (lapwrench never shares it)")
        return None


class UntrustedClients:
    """Installed on a running :class:`viser.ViserServer` (by :class:`~lapwrench.ui.app.UiApp`) until
    :meth:`close`: what its clients do wrong goes to ``incidents``, one line each, rate-limited."""

    def __init__(self, server: Any, incidents: IncidentLog | None = None) -> None:
        self.incidents = incidents if incidents is not None else IncidentLog(WHO)
        self.filter = ClientFailures(self.incidents)
        if isinstance(server, PageServer):
            server.incidents = self.incidents
        # First among the logger's filters: viser adds its own at its first HTTP request (every viser
        # server of the process adds one, and none is taken off), which drops a refused handshake
        # without a word; ours tells it, in one line.
        logging.getLogger(WEBSOCKETS_LOGGER).filters.insert(0, self.filter)
        # once for the process, never taken off: it says only that a client sent a mis-shaped tuple
        warnings.filterwarnings("ignore", message=ANNOTATION_WARNING, category=UserWarning, module=r"viser\.")
        self.loop: asyncio.AbstractEventLoop = server.get_event_loop()
        self.previous = self.loop.get_exception_handler()
        # Setting the handler is one attribute assignment, read by the loop when a task fails: safe from
        # this thread; scheduling it on the loop instead would leave a window where the default is used.
        self.loop.set_exception_handler(self.loop_exception)

    def loop_exception(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        """viser's event loop's exception handler: a failed task of viser's receive path is an incident
        line; anything else goes on to the handler that was there (asyncio's default: the traceback)."""
        exc = context.get("exception")
        if isinstance(exc, BaseException) and (failure := receive_failure(exc)) is not None:
            self.incidents.report(incident(*failure, exc, None))
        elif self.previous is not None:
            self.previous(loop, context)
        else:
            loop.default_exception_handler(context)

    def close(self) -> None:
        """Take the filter and the handler off; say how many incidents were not shown, if any."""
        logging.getLogger(WEBSOCKETS_LOGGER).removeFilter(self.filter)
        if self.loop.get_exception_handler() == self.loop_exception:
            self.loop.set_exception_handler(self.previous)
        self.incidents.close()
