"""One shape for every extension point: a named registry that each extension's own file joins.

Actions, monitor kinds, strategies, codecs, fault families and DeFT's frame rules are each a
``Registry``: an extension is one module that calls ``REGISTRY.register(name,
value)`` (or decorates its class with ``@REGISTRY.register_class``) at import
time. A registry made with a ``package`` imports every module of that package
the first time it is read, so dropping a file into the package is all it
takes; nothing lists the members by hand. Lists a user sees (the spec
reader's "supported: …", the command line's ``choices``) derive from
``names()``.

The registry is pure bookkeeping: it never imports a module named by a user's
input, only the modules of its own package (or those a test imports itself).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

from astaa_deft.model.errors import AstaaDeftError

T = TypeVar("T")
C = TypeVar("C", bound=type)


class DuplicateExtension(AstaaDeftError, RuntimeError):
    """Two extensions of one kind claim the same name (a programming error, found at import)."""


class Registry(Generic[T]):
    """Extensions of one kind by name, in the order their names sort.

    ``kind`` names the kind in messages ("action", "monitor kind"…);
    ``package`` is the dotted package whose modules are the extensions
    (imported on first read; modules whose name starts with ``_`` or is in
    ``skip`` are not extensions).
    """

    def __init__(self, kind: str, package: str | None = None, *, skip: tuple[str, ...] = ("base",)) -> None:
        self.kind = kind
        self._package = package
        self._skip = skip
        self._members: dict[str, T] = {}
        self._loaded = package is None
        self._loading = False

    def register(self, name: str, value: T) -> T:
        """Add ``value`` under ``name``; a second extension of the same name is refused."""
        if not name:
            raise DuplicateExtension(f"a {self.kind} needs a name")
        if name in self._members and self._members[name] is not value:
            raise DuplicateExtension(f"two {self.kind}s named {name!r}: {self._members[name]!r} and {value!r}")
        self._members[name] = value
        return value

    def register_class(self, cls: C) -> C:
        """Class decorator: register ``cls`` under its ``name`` attribute."""
        self.register(cls.name, cls)  # type: ignore[arg-type,attr-defined]  # a class registry's T is that class type
        return cls

    def unregister(self, name: str) -> None:
        """Remove ``name`` (tests that add a throwaway extension take it out again)."""
        self._members.pop(name, None)

    def _load(self) -> None:
        if self._loaded or self._loading:
            return
        self._loading = True
        try:
            assert self._package is not None
            package = importlib.import_module(self._package)
            for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
                if info.name.startswith("_") or info.name in self._skip:
                    continue
                importlib.import_module(f"{self._package}.{info.name}")
            self._loaded = True
        finally:
            self._loading = False

    def __getitem__(self, name: str) -> T:
        self._load()
        return self._members[name]

    def get(self, name: str) -> T | None:
        self._load()
        return self._members.get(name)

    def __contains__(self, name: object) -> bool:
        self._load()
        return name in self._members

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        self._load()
        return len(self._members)

    def names(self) -> tuple[str, ...]:
        """The registered names, sorted: what a user may write."""
        self._load()
        return tuple(sorted(self._members))

    def items(self) -> list[tuple[str, T]]:
        self._load()
        return sorted(self._members.items())

    def values(self) -> list[T]:
        return [value for _, value in self.items()]

    def decorator(self, name: str) -> Callable[[T], T]:
        """``@REGISTRY.decorator("name")`` over a function or object: register it under ``name``."""
        def wrap(value: T) -> T:
            return self.register(name, value)
        return wrap


class NamesOf:
    """A registry's names, read when first asked: ``choices`` for argparse that import no extension until needed.

    ``names`` returns the registry's ``names()`` (importing the registry may
    be costly: a command line builds every command's parser, and only
    ``fuzz`` needs the strategies). argparse only iterates the choices for
    help and error messages and tests membership of a value given.
    """

    def __init__(self, names: Callable[[], tuple[str, ...]]) -> None:
        self._names = names

    def __contains__(self, name: object) -> bool:
        return name in self._names()

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())
