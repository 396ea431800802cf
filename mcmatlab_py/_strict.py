"""Strict attributes: a misspelled or unknown name raises at once, with a suggestion.

MCmatlab's classes reject unknown properties; a Python object would silently grow
a new attribute (``model.MC.nPhotonsRequested = 1000`` would leave
``n_photons_requested`` unset). :class:`StrictAttributes` makes such a line fail
where it is written, naming the closest known name, the snake_case form of a
camelCase MCmatlab name, or saying that the MCmatlab feature is not built yet.
"""

from __future__ import annotations

import dataclasses
import re
from typing import ClassVar

from fem.checks import closest_name

__all__ = ["NotBuiltError", "StrictAttributes", "camel_to_snake"]


_KNOWN: dict[type, frozenset[str]] = {}  # class -> its known attribute names


class NotBuiltError(NotImplementedError, AttributeError):
    """An MCmatlab feature that this port does not have (yet).

    Also an :class:`AttributeError`, so that ``hasattr`` and ``getattr(obj, name, default)``
    keep working on the objects.
    """


def camel_to_snake(name: str) -> str:
    """``nPhotonsRequested`` -> ``n_photons_requested``.

    A run of capitals is one acronym, and MCmatlab writes the next word in lower case
    after it: ``GPUdevice`` -> ``gpu_device``, ``FRdepIterations`` -> ``fr_dep_iterations``.
    """
    s = re.sub(r"([A-Z]{2,})(?=[a-z])", r"\1_", name)
    s = re.sub(r"([a-z0-9])([A-Z])", r"\1_\2", s)
    return re.sub(r"_+", "_", s).lower()


class StrictAttributes:
    """Mixin for the user-facing classes: only known attributes may be set or read.

    Known are the dataclass fields, properties, the names in ``_extra_attributes``
    and any name starting with ``_``. Subclasses may list

    * ``_renamed``: MCmatlab name -> our name, where the snake_case rule does not give it;
    * ``_not_built``: MCmatlab names (and their snake_case forms are derived) of
      features not built yet; using one raises :class:`NotBuiltError`.
    * ``_instead``: MCmatlab name -> how this port does the same, for features it does
      another way; using one raises :class:`NotBuiltError` with that advice.
    """

    _owner_label: ClassVar[str] = ""  #: how error messages name the object, e.g. "MC"
    _extra_attributes: ClassVar[tuple[str, ...]] = ()
    _renamed: ClassVar[dict[str, str]] = {}
    _not_built: ClassVar[tuple[str, ...]] = ()
    _instead: ClassVar[dict[str, str]] = {}

    @classmethod
    def _known_attributes(cls) -> frozenset[str]:
        names = _KNOWN.get(cls)
        if names is None:
            found = set(cls._extra_attributes)
            if dataclasses.is_dataclass(cls):
                found.update(f.name for f in dataclasses.fields(cls))
            for klass in cls.__mro__:
                found.update(k for k, v in vars(klass).items() if isinstance(v, property))
            names = _KNOWN[cls] = frozenset(found)
        return names

    def __setattr__(self, name: str, value) -> None:
        if not name.startswith("_") and name not in self._known_attributes():
            raise self._unknown(name)
        object.__setattr__(self, name, value)

    def __getattr__(self, name: str):
        # only called when the normal lookup failed
        if name.startswith("_"):
            raise AttributeError(name)
        prop = getattr(type(self), name, None)
        if isinstance(prop, property):
            return prop.fget(self)  # a getter that failed: let its own error show
        raise self._unknown(name)

    @classmethod
    def _unknown(cls, name: str) -> AttributeError:
        label = cls._owner_label or cls.__name__
        known = cls._known_attributes()
        snake = camel_to_snake(name)
        head = f"{label} has no attribute {name!r}"
        if name in cls._renamed:
            return AttributeError(f"{head}: MCmatlab's {name} is {label}.{cls._renamed[name]} here")
        # our names keep the capitals of math names (NFR, T_initial): compare case-blind
        by_lower = {k.lower(): k for k in known}
        if snake != name.lower() and snake in by_lower:
            return AttributeError(f"{head}: MCmatlab's {name} is {label}.{by_lower[snake]} here "
                                  "(snake_case)")
        instead = {**cls._instead, **{camel_to_snake(k): v for k, v in cls._instead.items()}}
        if name in instead or snake in instead:
            return NotBuiltError(f"MCmatlab's {label}.{name} has no counterpart in this port: "
                                 f"{instead.get(name) or instead[snake]}")
        not_built = set(cls._not_built) | {camel_to_snake(n) for n in cls._not_built}
        if name in not_built or snake in not_built:
            return NotBuiltError(f"MCmatlab's {label}.{name} is not built yet")
        methods = {k for klass in cls.__mro__ if klass is not object
                   for k, v in vars(klass).items() if callable(v) and not k.startswith("_")}
        if snake != name and snake in methods:
            return AttributeError(f"{head}: MCmatlab's {name} is {label}.{snake}() here")
        candidates = sorted(known | methods)
        close = closest_name(name, candidates)
        if close is None and snake != name:
            close = closest_name(snake, candidates)
        hint = f"; did you mean {close!r}?" if close else ""
        return AttributeError(f"{head}{hint}")
