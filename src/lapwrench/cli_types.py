"""Argument types of the ``lapwrench`` command line: each refuses a bad value at parse time.

Every subcommand's numbers, CPU lists, addresses and output paths go through these ``type=``
callables, so argparse itself reports a bad value (``usage: ...`` then one ``error:`` line naming the
argument) and exits with code 2, before anything is loaded, simulated or connected. A value is
quoted with at most :data:`QUOTE_CHARS` characters, so a hostile megabyte of text stays one short line.

Written once here and shared by :mod:`lapwrench.cli`, :mod:`lapwrench.hardware.cli` and
:mod:`lapwrench.perception.cli`.
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import os
import re
import socket
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

QUOTE_CHARS = 60
MAX_MESSAGE_CHARS = 200

__all__ = [
    "ArgumentParser",
    "cpu_list",
    "float_in",
    "hex_bytes",
    "host_address",
    "int_in",
    "nonnegative_float",
    "nonnegative_int",
    "output_dir",
    "output_file",
    "positive_float",
    "positive_int",
    "quote",
    "writable_dir_problem",
    "writable_file_problem",
]


def quote(value: object) -> str:
    """``repr`` of ``value`` cut to about :data:`QUOTE_CHARS` characters: its start and, as a file
    name sits at the end of a path, its last characters, joined by ``...``."""
    text = str(value)
    if len(text) <= QUOTE_CHARS:
        return repr(text)
    tail = QUOTE_CHARS // 3
    return repr(text[: QUOTE_CHARS - tail - 3] + "..." + text[-tail:])


class ArgumentParser(argparse.ArgumentParser):
    """An :class:`argparse.ArgumentParser` whose error line never exceeds :data:`MAX_MESSAGE_CHARS`.

    argparse quotes a bad choice or an unknown argument whole; this keeps the message one short line
    (its subparsers are of this class too, as ``add_subparsers`` uses the parent's class).
    """

    def error(self, message: str) -> NoReturn:
        message = " ".join(message.split())
        if len(message) > MAX_MESSAGE_CHARS:
            message = message[: MAX_MESSAGE_CHARS - 3] + "..."
        super().error(message)


def _fail(what: str, text: str) -> NoReturn:
    raise argparse.ArgumentTypeError(f"{what}, got {quote(text)}")


def _parse_float(text: str, what: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError, OverflowError):
        _fail(what, text)
    if not math.isfinite(value):
        _fail(what, text)
    return value


def _parse_int(text: str, what: str) -> int:
    try:
        return int(str(text).strip(), 10)
    except (TypeError, ValueError):  # includes more digits than int() converts
        _fail(what, text)


def float_in(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False) -> Callable[[str], float]:
    """A finite float type in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``; ``None``: unbounded)."""
    if lo is None and hi is None:
        what = "must be a finite number"
    elif hi is None:
        what = f"must be a finite number {'>' if lo_open else '>='} {lo:g}"
    elif lo is None:
        what = f"must be a finite number <= {hi:g}"
    else:
        what = f"must be a number from {lo:g} {'(excluded) ' if lo_open else ''}to {hi:g}"

    def parse(text: str) -> float:
        value = _parse_float(text, what)
        if lo is not None and (value < lo or (lo_open and value == lo)):
            _fail(what, text)
        if hi is not None and value > hi:
            _fail(what, text)
        return value

    parse.__name__ = "number"  # argparse names the type in some messages
    return parse


def int_in(lo: int | None = None, hi: int | None = None) -> Callable[[str], int]:
    """A whole-number type in ``[lo, hi]`` (``None``: unbounded on that side)."""
    if hi is None:
        what = "must be a whole number" + ("" if lo is None else f" >= {lo}")
    elif lo is None:
        what = f"must be a whole number <= {hi}"
    else:
        what = f"must be a whole number from {lo} to {hi}"

    def parse(text: str) -> int:
        value = _parse_int(text, what)
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            _fail(what, text)
        return value

    parse.__name__ = "whole number"
    return parse


def positive_float(text: str) -> float:
    """A finite number > 0."""
    value = _parse_float(text, "must be a positive finite number")
    if value <= 0:
        _fail("must be a positive finite number", text)
    return value


def nonnegative_float(text: str) -> float:
    """A finite number >= 0."""
    value = _parse_float(text, "must be a finite number >= 0")
    if value < 0:
        _fail("must be a finite number >= 0", text)
    return value


positive_int = int_in(1)
nonnegative_int = int_in(0)


def cpu_list(text: str) -> str:
    """A comma-separated list of CPU numbers this machine has (``'1'``, ``'2,3'``); returned as text.

    An empty string means "no pinning" and passes unchanged.
    """
    if text == "":
        return text
    what = "must be comma-separated CPU numbers, e.g. 1 or 2,3"
    parts = text.split(",")
    if not all(re.fullmatch(r"\s*\d{1,4}\s*", p) for p in parts):
        _fail(what, text)
    cpus = [int(p) for p in parts]
    n = os.cpu_count() or 1
    missing = [c for c in cpus if c >= n]
    if missing:
        _fail(f"names CPU {missing[0]}, but this machine has CPUs 0 to {n - 1}", text)
    return ",".join(str(c) for c in cpus)


_HOST_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")


def host_address(text: str) -> str:
    """An IPv4/IPv6 address or a host name (RFC 1123 labels); returned stripped."""
    what = "must be an IP address or a host name"
    host = text.strip()
    if not host or len(host) > 253:
        _fail(what, text)
    try:
        ipaddress.ip_address(host)
    except ValueError:
        pass
    else:
        return host
    if re.fullmatch(r"[\d.]+", host):  # all digits and dots, but not an IPv4 address: 300.1.2.3, 1.2.3
        _fail(what, text)
    if not all(_HOST_LABEL.fullmatch(label) for label in host.rstrip(".").split(".")):
        _fail(what, text)
    return host


FOXGLOVE_DEFAULT = "127.0.0.1:8765"


def host_port(text: str) -> tuple[str, int]:
    """``HOST:PORT``, ``HOST`` or ``:PORT`` (defaults 127.0.0.1 and 8765; ``[v6]:PORT`` for IPv6);
    port 0 picks a free one."""
    default_host, default_port = FOXGLOVE_DEFAULT.split(":")
    body = text.strip()
    host, port_text = body, None
    if body.startswith("["):
        host, bracket, rest = body[1:].partition("]")
        if not bracket or (rest and not rest.startswith(":")):
            _fail("must be HOST:PORT, [IPv6]:PORT, HOST or :PORT", text)
        port_text = rest[1:] if rest else None
    elif body.count(":") == 1:
        host, port_text = body.split(":")
    host = host_address(host) if host else default_host
    port = int(default_port) if port_text is None else int_in(0, 65535)(port_text)
    return host, port


def listen_problem(host: str, port: int) -> str | None:
    """Why a server could not listen on ``host:port`` (address unknown, port taken), or None: a bind
    probe, released at once (port 0 always works)."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        return f"cannot resolve {host}: {exc}"
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as s:
        # as the servers bind (asyncio's and tokio's set it): a port left in TIME_WAIT by the last session's
        # clients is free to them, and Linux still refuses a port another socket listens on
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(address)
        except OSError as exc:
            return f"cannot listen on {host}:{port}: {exc.strerror or exc}"
    return None


def hex_bytes(text: str) -> bytes:
    """One to eight bytes written in hex (``AA55``, ``aa 55``, ``0xAA55``)."""
    what = "must be 1 to 8 bytes in hex, e.g. AA55"
    digits = "".join(text.split())
    if digits[:2].lower() == "0x":
        digits = digits[2:]
    if not re.fullmatch(r"(?:[0-9A-Fa-f]{2}){1,8}", digits):
        _fail(what, text)
    return bytes.fromhex(digits)


def _nearest_existing(path: Path) -> Path:
    for p in (path, *path.parents):
        if os.path.lexists(p):
            return p
    return Path(".")


def _path_problem(path: str | os.PathLike[str], check: Callable[[Path], str | None]) -> str | None:
    text = os.fspath(path)
    if text == "":
        return "is empty"
    if "\0" in text:
        return "contains a NUL character"
    try:
        return check(Path(text))
    except (OSError, ValueError) as exc:  # a name too long, a loop of links...
        return f"is not a usable path ({exc.strerror if isinstance(exc, OSError) else exc})"


def writable_dir_problem(path: str | os.PathLike[str]) -> str | None:
    """Why a folder could not be created or written at ``path`` (``None`` if it can), leaving nothing
    behind (a nameless temporary file probes the folder)."""
    return _path_problem(path, _dir_problem)


def writable_file_problem(path: str | os.PathLike[str]) -> str | None:
    """Why a file could not be written at ``path`` (``None`` if it can), leaving nothing behind.

    A folder given for a file, a parent that is a file, or an unwritable file or folder is a problem;
    missing parent folders are fine when they can be created.
    """
    return _path_problem(path, _file_problem)


def _writable(folder: Path) -> bool:
    """Whether files can be made in ``folder``: its permissions, then a nameless temporary file made and
    dropped there (root passes every permission check, but /proc, /sys and read-only mounts refuse files)."""
    if not os.access(folder, os.W_OK | os.X_OK):
        return False
    try:
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def _dir_problem(p: Path) -> str | None:
    if p.exists():
        if not p.is_dir():
            return "is a file, not a folder"
        return None if _writable(p) else "is not writable"
    base = _nearest_existing(p.absolute())
    if not base.is_dir():
        return f"cannot be created: {quote(str(base))} is not a folder"
    if not _writable(base):
        return f"cannot be created: {quote(str(base))} is not writable"
    return None


def _file_problem(p: Path) -> str | None:
    if p.is_dir():
        return "is a folder, not a file"
    if p.exists():
        return None if os.access(p, os.W_OK) else "is not writable"
    problem = _dir_problem(p.absolute().parent)
    return None if problem is None else f"cannot be written: its folder {quote(str(p.parent))} {problem}"


def output_file(text: str) -> str:
    """A file path that can be written (checked now, created later)."""
    problem = writable_file_problem(text)
    if problem:
        raise argparse.ArgumentTypeError(f"{quote(text)} {problem}")
    return text


def output_dir(text: str) -> str:
    """A folder path that exists and is writable, or can be created (checked now, created later)."""
    problem = writable_dir_problem(text)
    if problem:
        raise argparse.ArgumentTypeError(f"{quote(text)} {problem}")
    return text


def display_path(path: str | Path) -> str:
    """``path`` as text every terminal takes: bytes of the name that are not UTF-8 (which Python keeps as
    lone surrogates) as ``\\xNN``. Printed as it is, such a path ends the program with a
    UnicodeEncodeError when stdout is strict UTF-8 (a UTF-8 locale other than C.UTF-8)."""
    return os.fsencode(str(path)).decode("utf-8", "backslashreplace")
