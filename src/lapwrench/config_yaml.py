"""The YAML reader behind :func:`lapwrench.config.load`: small, strict and unable to explode.

A configuration is a two-level mapping of names to scalars, so this reader refuses everything
else YAML can express before any of it is expanded or constructed:

* files over :data:`MAX_BYTES` (read at most that many bytes plus one, never the whole file);
* text that is not UTF-8;
* anchors and aliases (``&a`` / ``*a``): an alias bomb of a few hundred bytes expands to gigabytes;
* explicit tags other than the core ones, merge keys (``<<``), timestamps (read as plain text);
* numbers YAML 1.1 reads otherwise than they are written: ``010`` (octal 8) and ``1:30`` (base 60: 90),
  where YAML 1.2 and every reader of a config mean 10 and a time (:func:`_construct_int`);
* a value its explicit core tag cannot hold (``!!bool maybe``, ``!!int ''``): PyYAML's constructors raise
  KeyError or IndexError there;
* nesting deeper than :data:`MAX_DEPTH`, more than :data:`MAX_NODES` nodes, numbers longer than
  :data:`MAX_NUMBER_CHARS` characters (Python's int() of a huge literal is slow or raises);
* a key that is not a plain scalar, and a key given twice in one mapping (YAML would keep the
  last one silently).

Each refusal is a :class:`YamlConfigError` naming the file and the line. Messages quote at most a
short prefix of any value (:func:`short`).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml
from yaml.events import AliasEvent, CollectionStartEvent, ScalarEvent
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

MAX_BYTES = 1 << 20  # 1 MiB: the shipped default.yaml is 6 kB
MAX_DEPTH = 6  # a config nests 2 levels (section: key: value); a little more gives a clear type error
MAX_NODES = 10_000  # the full config has ~110 nodes
MAX_NUMBER_CHARS = 1000  # a float needs ~25 characters; int() of longer digit strings is slow or refused
QUOTE_CHARS = 60  # longest prefix of a value quoted in an error message

_CORE = "tag:yaml.org,2002:"
_ALLOWED_TAGS = {_CORE + t for t in ("str", "int", "float", "bool", "null", "map", "seq")} | {"!"}
_NUMBER_TAGS = {_CORE + "int", _CORE + "float"}
_IMPLICIT_DROPPED = {_CORE + "timestamp", _CORE + "merge", _CORE + "value"}


class YamlConfigError(ValueError):
    """A config file cannot be read as a plain YAML mapping; the message names the file and line."""


def short(value: Any, limit: int = QUOTE_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters (plus "..."), for quoting a bad value in an error.

    Never builds the full repr of a long string or a huge integer (that can take seconds).
    """
    if isinstance(value, str) and len(value) > limit:
        return repr(value[:limit]) + "..."
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 4 * limit:
        return f"<integer of about {int(value.bit_length() * 0.30103)} digits>"
    if isinstance(value, list | tuple | dict | set) and len(value) > limit:
        return f"<{type(value).__name__} of {len(value)} items>"
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def cut(text: str, limit: int = 300) -> str:
    """``text`` cut to ``limit`` characters (plus "..."): an error message stays one screen line or so."""
    return text if len(text) <= limit else text[:limit] + "..."


def printable(text: str, limit: int = 100) -> str:
    """``text`` (a file's name) for an error message: characters that are not printable (a line break, a
    terminal escape, an undecodable byte) written as escapes, then cut to ``limit`` (:func:`cut`)."""
    shown = "".join(c if c.isprintable() else c.encode("unicode_escape", "backslashreplace").decode("ascii")
                    for c in text[: limit + 1])
    return cut(shown, limit)


def read_text(path: Path, source: str) -> str:
    """The UTF-8 text of the config file at ``path``, refusing anything that is not a small text file."""
    try:
        if path.is_dir():
            raise YamlConfigError(f"config file {source} is a directory, not a file")
        if not path.exists():
            raise YamlConfigError(f"config file not found: {source}")
        if not path.is_file():
            raise YamlConfigError(f"config file {source} is not a regular file")
        with path.open("rb") as f:
            raw = f.read(MAX_BYTES + 1)
    except OSError as exc:
        raise YamlConfigError(f"config file {source} cannot be read: {exc.strerror or exc}") from exc
    if len(raw) > MAX_BYTES:
        raise YamlConfigError(f"config file {source} is larger than {MAX_BYTES // 1024} KiB; a config is a few kB")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise YamlConfigError(f"config file {source} is not UTF-8 text (byte {exc.start})") from exc


def _line(node_or_event: Any) -> int:
    return int(node_or_event.start_mark.line) + 1


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that refuses anchors, aliases, odd tags, deep nesting and overlong numbers as it composes,
    and names the line of any value it cannot construct."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._nodes = 0

    def compose_node(self, parent: Node | None, index: Any) -> Node:
        event = self.peek_event()
        if isinstance(event, AliasEvent):
            raise YamlConfigError(f"line {_line(event)}: YAML aliases (*name) are not allowed in a config file")
        if getattr(event, "anchor", None) is not None:
            raise YamlConfigError(f"line {_line(event)}: YAML anchors (&name) are not allowed in a config file")
        tag = getattr(event, "tag", None)
        if tag is not None and tag not in _ALLOWED_TAGS:
            raise YamlConfigError(f"line {_line(event)}: YAML tag {short(tag)} is not allowed in a config file")
        if isinstance(event, ScalarEvent) and len(event.value) > MAX_NUMBER_CHARS:
            resolved = tag if tag not in (None, "!") else self.resolve(ScalarNode, event.value, event.implicit)
            if resolved in _NUMBER_TAGS:
                raise YamlConfigError(f"line {_line(event)}: number longer than {MAX_NUMBER_CHARS} characters")
        self._nodes += 1
        if self._nodes > MAX_NODES:
            raise YamlConfigError(f"line {_line(event)}: more than {MAX_NODES} YAML nodes; a config has ~100")
        depth = self._depth + isinstance(event, CollectionStartEvent)
        if depth > MAX_DEPTH:
            raise YamlConfigError(f"line {_line(event)}: nested deeper than {MAX_DEPTH} levels")
        self._depth = depth
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= isinstance(event, CollectionStartEvent)

    def construct_object(self, node: Node, deep: bool = False) -> Any:
        """The node's value; a constructor's own error (``!!bool maybe`` is a KeyError, ``!!int ''`` an
        IndexError in PyYAML) becomes a :class:`YamlConfigError` naming the node's line."""
        try:
            return super().construct_object(node, deep)
        except YamlConfigError:
            raise
        except (ArithmeticError, LookupError, TypeError, ValueError) as exc:
            kind, value = str(node.tag).removeprefix(_CORE), short(node.value)
            raise YamlConfigError(f"line {_line(node)}: YAML value {value} is not a valid !!{kind}") from exc


def _construct_int(loader: _StrictLoader, node: ScalarNode) -> int:
    """An integer as YAML 1.2 and a reader see it: refuses what YAML 1.1 would read otherwise (``010`` is 8
    there, ``1:30`` is 90); hexadecimal (``0x``) and binary (``0b``) are read as in both."""
    text = str(loader.construct_scalar(node))
    digits = text.replace("_", "").lstrip("+-")
    if ":" in digits:
        raise YamlConfigError(f"line {_line(node)}: {short(text)} {_SEXAGESIMAL}")
    if len(digits) > 1 and digits[0] == "0" and digits[1].isdigit():
        raise YamlConfigError(f"line {_line(node)}: {short(text)} has a leading zero: YAML 1.1 reads it as an "
                              "octal number; write the number without it")
    return int(yaml.SafeLoader.construct_yaml_int(loader, node))


def _construct_float(loader: _StrictLoader, node: ScalarNode) -> float:
    """A float, refusing YAML 1.1's base-60 form (``5:00.0`` is 300.0 there)."""
    text = str(loader.construct_scalar(node))
    if ":" in text:
        raise YamlConfigError(f"line {_line(node)}: {short(text)} {_SEXAGESIMAL}")
    return float(yaml.SafeLoader.construct_yaml_float(loader, node))


_SEXAGESIMAL = "is a base-60 number in YAML 1.1 (1:30 reads as 90); write the number in decimal, or quote a text"
_StrictLoader.add_constructor(_CORE + "int", _construct_int)
_StrictLoader.add_constructor(_CORE + "float", _construct_float)


# timestamps stay plain strings (a config has none; "2001-02-30" would raise ValueError in datetime),
# and "<<" / "=" are ordinary keys (refused later as unknown) instead of merge / value keys
_StrictLoader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag not in _IMPLICIT_DROPPED]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
# YAML 1.1 reads 1e-9 and 5e-4 (no dot) as text; a config means a number (as YAML 1.2 does)
_StrictLoader.add_implicit_resolver(
    _CORE + "float", re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"), list("-+0123456789")
)


def _check_keys(loader: _StrictLoader, node: Node, path: str, lines: dict[str, int]) -> None:
    """Refuse non-scalar and duplicate keys; record the line of every key path in ``lines``."""
    if isinstance(node, SequenceNode):
        for i, item in enumerate(node.value):
            lines.setdefault(f"{path}[{i}]", _line(item))  # an element's own line ("scope.grip_com[2]")
            _check_keys(loader, item, f"{path}[{i}]", lines)
        return
    if not isinstance(node, MappingNode):
        return
    seen: dict[Any, int] = {}
    for key_node, value_node in node.value:
        if not isinstance(key_node, ScalarNode):
            raise YamlConfigError(f"line {_line(key_node)}: a config key must be a plain name, not a collection")
        key = loader.construct_object(key_node)
        name = f"{path}.{key}" if path else str(key)
        if key in seen:
            raise YamlConfigError(
                f"line {_line(key_node)}: config key {short(name)} appears twice (first on line {seen[key]})"
            )
        seen[key] = _line(key_node)
        lines.setdefault(name, _line(key_node))
        _check_keys(loader, value_node, name, lines)


def _describe(exc: yaml.YAMLError, text: str) -> str:
    """One line for a YAML syntax error: where, and what (PyYAML's own text spans several lines)."""
    if isinstance(exc, yaml.MarkedYAMLError) and exc.problem_mark is not None:
        mark, what = exc.problem_mark, exc.problem or exc.context or "syntax error"
        where = f"line {mark.line + 1}, column {mark.column + 1}: "
    elif isinstance(exc, yaml.reader.ReaderError):
        code = ord(exc.character) if isinstance(exc.character, str) else int(exc.character)
        where, what = f"line {text.count(chr(10), 0, exc.position) + 1}: ", f"character #x{code:04x}: {exc.reason}"
    else:
        where, what = "", str(exc).strip().split("\n")[0]
    return f"is not valid YAML: {where}{cut(' '.join(str(what).split()), 200)}"


def parse(text: str) -> tuple[Any, dict[str, int]]:
    """The data of one YAML document and the line of each key path (``"rcm.Kp"``), strictly.

    Raises :class:`YamlConfigError` ("line N: ..." or "is not valid YAML: ...", to follow the
    file's name) on anything refused.
    """
    try:
        loader = _StrictLoader(text)  # the reader refuses control characters here already
    except yaml.YAMLError as exc:
        raise YamlConfigError(_describe(exc, text)) from exc
    try:
        node = loader.get_single_node()
        if node is None:
            return None, {}
        lines: dict[str, int] = {}
        _check_keys(loader, node, "", lines)
        return loader.construct_document(node), lines
    except yaml.YAMLError as exc:
        raise YamlConfigError(_describe(exc, text)) from exc
    except (ValueError, OverflowError, TypeError) as exc:  # a constructor's own error (belt and braces)
        if isinstance(exc, YamlConfigError):
            raise
        raise YamlConfigError(f"is not valid YAML: {cut(' '.join(str(exc).split()), 200)}") from exc
    finally:
        loader.dispose()
