"""Registries of interchangeable models: name -> kernel code, each entry with its description and citation.

A registry is the one place where a choice between models (drag laws, hindrance corrections, coalescence-probability
forms, coalescence rules) is listed: the case schema takes its allowed values from it, the Numba kernels switch on
its integer codes, and the tests loop over its entries. Adding a model means one entry here plus its branch in the
law that switches on the code.

Indexing a registry by name gives the integer code the kernels take (``DRAG_LAWS["stokes"] == 0``), so a registry
stands in for the plain ``{name: code}`` dicts it replaces; :meth:`Registry.entry` gives the whole record.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass


@dataclass(frozen=True)
class Entry:
    """One registered model.

    name: the key used in case files; code: the integer the Numba kernels switch on; description: one line on what
    the model does; citation: where it comes from (author, year, journal or book).
    """

    name: str
    code: int
    description: str
    citation: str


class Registry(Mapping):
    """Frozen, ordered mapping name -> kernel code (int) of one kind of model, with an :class:`Entry` per name.

    Order is the order of registration (the first entry is listed first in the case reference). Names and codes
    are unique; an unknown name raises ``KeyError`` naming the allowed ones.
    """

    __slots__ = ("kind", "_entries", "_by_name", "_by_code")

    def __init__(self, kind: str, *entries: Entry):
        if not entries:
            raise ValueError(f"registry {kind!r} has no entries")
        by_name, by_code = {}, {}
        for e in entries:
            if not isinstance(e, Entry):
                raise TypeError(f"registry {kind!r}: {e!r} is not an Entry")
            if type(e.code) is not int:
                raise TypeError(f"registry {kind!r}: code of {e.name!r} is {e.code!r}, not an int")
            if not (e.description.strip() and e.citation.strip()):
                raise ValueError(f"registry {kind!r}: {e.name!r} needs a description and a citation")
            if e.name in by_name or e.code in by_code:
                raise ValueError(f"registry {kind!r}: name {e.name!r} or code {e.code} registered twice")
            by_name[e.name] = e
            by_code[e.code] = e
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "_entries", tuple(entries))
        object.__setattr__(self, "_by_name", by_name)
        object.__setattr__(self, "_by_code", by_code)

    def __setattr__(self, name, value):
        raise AttributeError(f"registry {self.kind!r} is frozen")

    def __delattr__(self, name):
        raise AttributeError(f"registry {self.kind!r} is frozen")

    def __getitem__(self, name: str) -> int:
        return self.entry(name).code

    def __iter__(self):
        return (e.name for e in self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __reduce__(self):
        return (Registry, (self.kind, *self._entries))

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: " + ", ".join(f"{e.name}={e.code}" for e in self._entries) + ")"

    def entry(self, name: str) -> Entry:
        """The entry registered as ``name``; KeyError naming the allowed names otherwise."""
        try:
            return self._by_name[name]
        except (KeyError, TypeError):
            raise KeyError(f"{self.kind}: {name!r} is not one of {', '.join(map(repr, self.names()))}") from None

    @property
    def entries(self) -> tuple[Entry, ...]:
        """All entries, in registration order."""
        return self._entries

    def names(self) -> tuple[str, ...]:
        """The allowed names, in registration order (the case schema's choices)."""
        return tuple(e.name for e in self._entries)

    def name_of(self, code: int) -> str:
        """The name registered with kernel code ``code`` (for messages and outputs)."""
        try:
            return self._by_code[code].name
        except KeyError:
            raise KeyError(f"{self.kind}: no entry has code {code!r}") from None
