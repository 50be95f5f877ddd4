"""Typed data from files, with every mistake said in one sentence.

Scenario files, netem profiles and map feature properties are read into
msgspec Structs whose field types carry their bounds. msgspec says
``Expected `float` <= 15.0 - at `$.agent[0].speed```; ``convert`` turns
that into ``agent[0].speed: must be a number in (0, 15] m/s, got 1e+300``:
the key path (list indices from 0, as msgspec counts), what the key must
be, and the value found there. A field type says how it reads through
``msgspec.Meta``: ``description`` replaces the generic wording
(``[east, north] in metres``) and ``extra={"unit": "m/s"}`` follows a
number's bounds.
"""

from __future__ import annotations

import re
from typing import Any

import msgspec
from msgspec import inspect as mi

_WHERE = re.compile(r"^(?P<message>.*?)(?: - at `\$(?P<path>[^`]*)`)?$", re.S)
_STEP = re.compile(r"\.([^.\[]+)|\[(\d+)\]")
_FIELD = re.compile(r"field `([^`]+)`")
_SHOWN = 60  # characters of a value quoted in a message


class Invalid(ValueError):
    """Data that does not fit its type: ``path`` names the key (empty at the
    top), ``problem`` says what is wrong with it."""

    def __init__(self, path: str, problem: str) -> None:
        super().__init__(f"{path}: {problem}" if path else problem)
        self.path = path
        self.problem = problem


def convert(data: Any, kind: Any, *, at: str = "") -> Any:
    """``data`` as ``kind`` (a Struct or any type msgspec converts to), or an
    ``Invalid`` naming the key path, prefixed by ``at``."""
    try:
        return msgspec.convert(data, kind)
    except msgspec.ValidationError as error:
        raise _explain(error, kind, data, at) from None


def _explain(error: msgspec.ValidationError, kind: Any, data: Any, at: str = "") -> Invalid:
    """The ``Invalid`` that ``error``, raised converting ``data`` to ``kind``, means."""
    parts = _WHERE.match(str(error))
    assert parts is not None  # the pattern matches any text
    message = parts["message"]
    steps = [name or int(index) for name, index in _STEP.findall(parts["path"] or "")]
    node, value = _resolve(mi.type_info(kind), steps, data)
    named = _FIELD.search(message)
    if named and message.startswith("Object contains unknown field"):
        keys = ", ".join(_keys(node, value))
        return Invalid(_path(at, steps), f"unknown key {named[1]!r}; the keys there are {keys}")
    if named and message.startswith("Object missing required field"):
        field, _ = _resolve(node, [named[1]], value)
        return Invalid(_path(at, [*steps, named[1]]), f"must be given, as {describe(field)}")
    return Invalid(_path(at, steps), _problem(node, value))


def _problem(node: Any, value: Any) -> str:
    """What is wrong with ``value`` for the type ``node`` (a ``msgspec.inspect`` type)."""
    choices = _choices(node)
    if choices is not None:
        return not_one_of(value, choices)
    return f"must be {describe(node)}, got {_shown(value)}"


def not_one_of(value: Any, choices) -> str:
    """The problem of a ``value`` that is none of ``choices``, for checks msgspec cannot make."""
    return f"{_shown(value)} is not one of {', '.join(repr(c) for c in choices)}"


def describe(node: Any) -> str:
    """What a value of the type ``node`` is, in words: ``a number in (0, 15] m/s``."""
    if not isinstance(node, mi.Type):
        node = mi.type_info(node)
    unit = ""
    if isinstance(node, mi.Metadata):
        text = (node.extra_json_schema or {}).get("description")
        if text:
            return text
        unit = (node.extra or {}).get("unit", "")
        node = node.type
    if isinstance(node, mi.UnionType):
        return " or ".join(describe(t) for t in node.types if not isinstance(t, mi.NoneType))
    choices = _choices(node)
    if choices is not None:
        return f"one of {', '.join(repr(c) for c in choices)}"
    if isinstance(node, mi.IntType | mi.FloatType):
        return _number(node) + (f" {unit}" if unit else "")
    if isinstance(node, mi.BoolType):
        return "true or false"
    if isinstance(node, mi.StrType):
        if node.pattern:
            return f"a string matching {node.pattern}"
        return "a non-empty string" if node.min_length else "a string"
    if isinstance(node, mi.TupleType):
        return f"a list of {len(node.item_types)} items"
    if isinstance(node, mi.ListType | mi.VarTupleType | mi.SetType | mi.FrozenSetType):
        return f"a list of at least {node.min_length} items" if node.min_length else "a list"
    if isinstance(node, mi.StructType):
        required = ", ".join(repr(f.encode_name) for f in node.fields if f.required)
        return f"a table with {required}" if required else "a table"
    if isinstance(node, mi.DictType):
        return "a table"
    return type(node).__name__.removesuffix("Type").lower()


def _shown(value: Any) -> str:
    """``value`` as a message quotes it: TOML's ``true``, at most a line's worth."""
    text = ("true" if value else "false") if isinstance(value, bool) else repr(value)
    return text if len(text) <= _SHOWN else text[: _SHOWN - 3] + "..."


def _number(node) -> str:
    low, high = (node.gt if node.gt is not None else node.ge), (node.lt if node.lt is not None else node.le)
    if isinstance(node, mi.IntType):
        if low is not None and high is not None:
            return f"an integer from {low} to {high}"
        return f"an integer of at least {low}" if low is not None else "an integer"
    if low is None or high is None:
        return "a number"
    opening, closing = "(" if node.gt is not None else "[", ")" if node.lt is not None else "]"
    return f"a number in {opening}{_figure(low)}, {_figure(high)}{closing}"


def _figure(number: float) -> str:
    """``1e7`` rather than ``1e+07``."""
    return f"{number:g}".replace("e+0", "e").replace("e+", "e")


def _choices(node) -> tuple | None:
    if isinstance(node, mi.Metadata):
        node = node.type
    if isinstance(node, mi.LiteralType):
        return node.values
    if isinstance(node, mi.EnumType):
        return tuple(member.value for member in node.cls)
    return None


def _resolve(node, steps, data) -> tuple[Any, Any]:
    """The type and the value found at ``steps`` (field names and indices) down ``node`` and ``data``."""
    for step in steps:
        members = _tagged(_bare(node))
        if members and step == members[0].tag_field:
            return mi.LiteralType(tuple(m.tag for m in members)), _item(data, step)
        node = _chosen(node, data)
        if isinstance(node, mi.StructType):
            node = next((f.type for f in node.fields if f.encode_name == step), mi.AnyType())
        elif isinstance(node, mi.TupleType):
            node = node.item_types[step] if isinstance(step, int) and step < len(node.item_types) else mi.AnyType()
        elif isinstance(node, mi.DictType):
            node = node.value_type
        else:
            node = getattr(node, "item_type", mi.AnyType())
        data = _item(data, step)
    return node, data


def _bare(node):
    """``node`` without its metadata, and without ``None`` if it is optional."""
    if isinstance(node, mi.Metadata):
        node = node.type
    if isinstance(node, mi.UnionType):
        rest = [t for t in node.types if not isinstance(t, mi.NoneType)]
        if len(rest) == 1:
            return _bare(rest[0])
    return node


def _chosen(node, data):
    """``node`` bare, and of a tagged union the Struct whose tag ``data`` gives (else the first)."""
    node = _bare(node)
    members = _tagged(node)
    if not members:
        return node
    tag = data.get(members[0].tag_field) if isinstance(data, dict) else None
    return next((m for m in members if m.tag == tag), members[0])


def _tagged(node) -> list:
    """The Structs of a tagged union, or none."""
    if isinstance(node, mi.UnionType) and all(isinstance(t, mi.StructType) and t.tag_field for t in node.types):
        return list(node.types)
    return []


def _keys(node, value) -> list[str]:
    node = _chosen(node, value)
    if not isinstance(node, mi.StructType):
        return []
    return ([node.tag_field] if node.tag_field else []) + [f.encode_name for f in node.fields]


def _item(data, step):
    if isinstance(step, int):
        return data[step] if isinstance(data, list | tuple) and step < len(data) else None
    return data.get(step) if isinstance(data, dict) else None


def _path(at: str, steps) -> str:
    path = at
    for step in steps:
        path += f"[{step}]" if isinstance(step, int) else (f".{step}" if path else step)
    return path
