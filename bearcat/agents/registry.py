"""Where the code that decides things comes from: one registry per kind of
extension, built-ins and a user's own alike.

An ``Entry`` is one plug-in: its name, the msgspec Struct its scenario
options are read into (so a wrong key is named), the factory that makes it
from those options, a one-line summary, the traits it declares and where it
came from. A scenario names one in three ways:

- a short name: a built-in, or one that an installed distribution registers
  under the kind's entry-point group (``[project.entry-points."bearcat.behaviours"]``),
  found the way pytest finds its plugins;
- ``package.module:attribute``: anything importable;
- ``path/to/file.py:attribute``: a file of one's own, relative to the
  scenario file's folder.

The attribute is an ``Entry`` of the kind, or a class that subclasses the
kind's protocol, whose class attributes declare its options and traits:
declared, never probed. Built-ins are entries like any other; the only
thing that sets them apart is that their module is read first, so an
installed distribution cannot shadow one.

Every way of failing to get an entry is a ``PluginError`` of one sentence
naming the plug-in and what went wrong.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.metadata
import importlib.util
import inspect
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Generic, TypeVar

import msgspec

T = TypeVar("T")

BUILTIN = "bearcat"
"""The origin of the entries bearcat ships."""


class PluginError(ValueError):
    """A plug-in that cannot be had: the text names it and says why."""


@dataclass(frozen=True)
class Entry(Generic[T]):
    """One plug-in of a kind: ``factory(options, rng)`` makes it, where
    ``options`` is the scenario's options table read into ``options_type``
    and ``rng`` a generator seeded for it alone. ``traits`` are what it
    declares it does beyond the protocol (its registry lists the traits
    there are); ``origin`` where it comes from: ``bearcat``, a
    distribution's entry point or a module."""

    name: str
    options_type: type[msgspec.Struct]
    factory: Callable[..., T]
    summary: str
    traits: frozenset[str] = frozenset()
    origin: str = BUILTIN

    def has(self, trait: str) -> bool:
        return trait in self.traits


@dataclass
class Registry(Generic[T]):
    """The plug-ins of one ``kind`` (``behaviour``, ...): the built-ins that
    module ``builtins`` lists in its ``BUILTINS`` (name -> entry or class), those registered under the
    entry-point ``group``, and any ``module:attribute`` a scenario names.
    A class plug-in must subclass ``protocol``; ``traits`` are those an
    entry of this kind may declare."""

    kind: str
    plural: str
    group: str
    protocol: type
    builtins: str
    traits: frozenset[str] = frozenset()
    _builtin: dict[str, Entry[T]] | None = field(default=None, repr=False)
    _found: dict[str, Entry[T]] = field(default_factory=dict, repr=False)

    def builtin(self) -> dict[str, Entry[T]]:
        """The built-in entries, by name."""
        if self._builtin is None:
            listed = importlib.import_module(self.builtins).BUILTINS
            self._builtin = {name: self._checked(found, name, BUILTIN) for name, found in listed.items()}
        return self._builtin

    def names(self) -> list[str]:
        """The built-ins' names, then those installed distributions register."""
        return list(self.builtin()) + [p.name for p in self._points() if p.name not in self.builtin()]

    def get(self, ref: str, base: Path | None = None) -> Entry[T]:
        """The entry ``ref`` names; ``base`` is the folder a ``file.py:attribute`` is relative to."""
        if ref in self._found:
            return self._found[ref]
        if ref in self.builtin():
            return self.builtin()[ref]
        if ":" in ref:
            entry = self._from_reference(ref, base)
        else:
            point = next((p for p in self._points() if p.name == ref), None)
            if point is None:
                raise PluginError(
                    f"there is no {self.kind} {ref!r}; the {self.plural} are {', '.join(self.names())}, "
                    f"or name one of your own as module:attribute"
                )
            entry = self._from_point(point)
        self._found[ref] = entry
        return entry

    def entries(self) -> Iterator[Entry[T] | PluginError]:
        """Every built-in and installed entry, or the error that loading it gave."""
        yield from self.builtin().values()
        for point in self._points():
            if point.name in self.builtin():
                yield PluginError(
                    f"{self.kind} {point.name!r} of {_distribution(point)} is not used: a built-in has that name"
                )
                continue
            try:
                yield self.get(point.name)
            except PluginError as exc:
                yield exc

    def _points(self) -> list[importlib.metadata.EntryPoint]:
        return sorted(importlib.metadata.entry_points(group=self.group), key=lambda p: p.name)

    def _from_point(self, point: importlib.metadata.EntryPoint) -> Entry[T]:
        origin = f"{_distribution(point)} (entry point {self.group}:{point.name})"
        try:
            found = point.load()
        except Exception as exc:
            raise PluginError(
                f"{self.kind} {point.name!r} that {_distribution(point)} registers as {point.value} "
                f"cannot be loaded: {_said(exc)}"
            ) from None
        return self._checked(found, point.name, origin)

    def _from_reference(self, ref: str, base: Path | None) -> Entry[T]:
        where, _, attribute = ref.rpartition(":")
        if not where or not attribute:
            raise PluginError(f"{ref!r} is not a name nor module:attribute")
        module = _file_module(ref, where, base) if where.endswith(".py") else _import(ref, where)
        found: Any = module
        for part in attribute.split("."):
            if not hasattr(found, part):
                raise PluginError(f"{ref!r}: {where} has no attribute {attribute!r}")
            found = getattr(found, part)
        return self._checked(found, ref, where)

    def _checked(self, found: Any, name: str, origin: str) -> Entry[T]:
        """``found`` as an entry named ``name``: an entry already, or a class of the protocol."""
        if isinstance(found, Entry):
            entry: Entry[T] = replace(found, name=name, origin=origin)
        elif inspect.isclass(found) and self.protocol in inspect.getmro(found):
            declared: Any = found  # a subclass of the protocol, which declares Options and traits
            doc = inspect.getdoc(found) or ""
            if not hasattr(declared, "Options"):
                raise PluginError(f"{name!r} declares no Options: the type its options are read into")
            entry = Entry(
                name=name,
                options_type=declared.Options,
                factory=declared,
                summary=_first_sentence(doc),
                traits=frozenset(declared.traits),
                origin=origin,
            )
        else:
            raise PluginError(
                f"{name!r} is {_kind_of(found)}, neither an Entry nor a class that subclasses "
                f"bearcat.plugins.{self.protocol.__name__}"
            )
        if not (inspect.isclass(entry.options_type) and issubclass(entry.options_type, msgspec.Struct)):
            raise PluginError(f"{name!r}: its options type is {_kind_of(entry.options_type)}, not a Struct")
        unknown = sorted(entry.traits - self.traits)
        if unknown:
            known = ", ".join(sorted(self.traits)) or "none"
            raise PluginError(f"{name!r} declares trait {unknown[0]!r}; a {self.kind}'s traits are {known}")
        return entry


def _import(ref: str, module: str):
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        raise PluginError(f"{ref!r}: module {module} cannot be imported: {_said(exc)}") from None
    except Exception as exc:
        raise PluginError(f"{ref!r}: importing module {module} raised {_said(exc)}") from None


def _file_module(ref: str, where: str, base: Path | None):
    """The module of the file ``where``, relative to ``base``, loaded once per process under a
    name its resolved path decides, so two scenarios naming one file share its classes."""
    path = Path(where)
    if not path.is_absolute():
        path = (base or Path.cwd()) / path
    path = path.resolve()
    if not path.is_file():
        raise PluginError(f"{ref!r}: there is no file {path}")
    name = f"bearcat_plugin_{path.stem}_{hashlib.sha1(str(path).encode()).hexdigest()[:10]}"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None  # a .py file always has a source loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        del sys.modules[name]
        raise PluginError(f"{ref!r}: running {path} raised {_said(exc)}") from None
    return module


def _distribution(point: importlib.metadata.EntryPoint) -> str:
    dist = point.dist
    return f"distribution {dist.name}" if dist is not None else "an installed distribution"


def _said(exc: BaseException) -> str:
    text = str(exc).splitlines()[0][:200] if str(exc) else ""
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _kind_of(value: Any) -> str:
    if inspect.isclass(value):
        return f"the class {value.__module__}.{value.__qualname__}"
    return f"a {type(value).__name__}"


def _first_sentence(doc: str) -> str:
    """The first sentence of a docstring, on one line."""
    text = " ".join(doc.split())
    end = text.find(". ")
    return text if end < 0 else text[: end + 1]
