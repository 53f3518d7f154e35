"""One registry shape for every extension point, and one policy for a broken plug-in.

Checks, converters, exporters, effects, render backends, Rerun layers and physics engines
are each kept in a :class:`Registry`: a map from a name to a registered object, filled by

* the built-in modules of robogs, imported lazily on the first listing or look-up;
* user code calling the registry's ``register`` function;
* installed distributions, through the entry-point group of the registry
  (:data:`ENTRY_POINT_GROUPS`; see ``docs/plugins.md``), loaded on the first listing or
  look-up.

:meth:`Registry.entries` lists everything, usable or not, as :class:`Entry` records with a
status, a reason and the source (``"builtin"``, ``"user"`` or the name of the distribution
that declared the entry point). A plug-in that fails to load is never fatal: it is listed as
``"unavailable"`` with the reason, a :class:`PluginWarning` is emitted once for it, and
:meth:`Registry.get` raises a :class:`PluginError` that names the plug-in, its distribution
and the reason.

Example:
    >>> reg = Registry("doubler", "robogs.doublers", noun="doubler")
    >>> _ = reg.register("twice", lambda x: 2 * x, source="my-lab")
    >>> reg.get("twice")(21)
    42
    >>> reg.mark_unavailable("fast", "needs the optional package fastthing")
    >>> [(e.name, e.status, e.source) for e in reg.entries()]
    [('fast', 'unavailable', 'builtin'), ('twice', 'ok', 'my-lab')]
"""

from __future__ import annotations

import importlib
import types
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from importlib import metadata
from typing import Any, Generic, Literal, TypeVar

from .errors import InputError, RobogsError

__all__ = [
    "ENTRY_POINT_GROUPS",
    "BUILTIN",
    "USER",
    "Entry",
    "Registry",
    "PluginError",
    "PluginWarning",
    "RegistrationError",
]

#: registry kind -> entry-point group, one per extension point (declared in pyproject.toml)
ENTRY_POINT_GROUPS: dict[str, str] = {
    "checks": "robogs.checks",
    "converters": "robogs.converters",
    "exporters": "robogs.exporters",
    "effects": "robogs.effects",
    "backends": "robogs.backends",
    "layers": "robogs.layers",
    "engines": "robogs.engines",
}

#: source of entries registered by robogs itself
BUILTIN = "builtin"
#: source of entries registered at run time by code outside robogs and outside an entry point
USER = "user"

Status = Literal["ok", "unavailable"]
T = TypeVar("T")


class PluginError(RobogsError):
    """A registered name that cannot be used: its plug-in or optional dependency failed."""


class RegistrationError(RobogsError, ValueError):
    """A bad registration: a malformed name or object, or a name already taken.

    Also a ``ValueError``, so ``except ValueError`` around a registration keeps working.
    """


class PluginWarning(RuntimeWarning):
    """Emitted once per plug-in that failed to load."""


@dataclass(frozen=True)
class Entry(Generic[T]):
    """One listed name of a registry.

    Attributes:
        kind: the registry's kind (``"checks"``, ``"backends"``...).
        name: the registered name (for a plug-in that failed to load: its entry-point name).
        obj: the registered object; None when unavailable.
        status: ``"ok"`` or ``"unavailable"``.
        reason: why it is unavailable (empty when ok).
        source: ``"builtin"``, ``"user"``, or the distribution that declared the entry point.
    """

    kind: str
    name: str
    obj: T | None
    status: Status
    reason: str = ""
    source: str = BUILTIN

    @property
    def ok(self) -> bool:
        """Whether the entry can be used."""
        return self.status == "ok"


def _module_name(obj: Any) -> str:
    return str(getattr(obj, "__module__", "") or "")


def _register_object(reg: Registry[Any], name: str, obj: Any) -> None:
    """Default handling of an entry point's object: a module registered itself on import;
    anything else is registered under the entry point's name."""
    if not isinstance(obj, types.ModuleType):
        reg.register(name, obj)


class Registry(Generic[T]):
    """Name -> object, with lazily loaded built-ins and entry points.

    Args:
        kind: the registry's kind, a key of :data:`ENTRY_POINT_GROUPS` for robogs' own ones.
        group: the entry-point group it loads.
        noun: what one entry is called in messages (``"render backend"``).
        builtins: modules registering the built-in entries when imported; a mapping
            ``name -> module`` lets :meth:`get` import only the module of the name asked for.
        adopt: ``adopt(registry, entry_point_name, loaded_object)`` registers what an entry
            point loaded (default: a module registered itself; any other object is registered
            under the entry point's name).
        order: sort key of the listing (default: the name).
        module_of: the module defining an object, to tell built-in from user registrations.
        unknown_where: the ``where`` of the error for an unknown name (e.g. ``"--from"``).
    """

    def __init__(
        self,
        kind: str,
        group: str,
        *,
        noun: str,
        builtins: Sequence[str] | Mapping[str, str] = (),
        adopt: Callable[[Registry[T], str, Any], None] = _register_object,
        order: Callable[[Entry[T]], Any] | None = None,
        module_of: Callable[[T], str] = _module_name,
        unknown_where: str | None = None,
    ) -> None:
        self.kind, self.group, self.noun = kind, group, noun
        self._builtins = builtins
        self._adopt = adopt
        self._order = order or (lambda e: e.name)
        self._module_of = module_of
        self._unknown_where = unknown_where
        self._entries: dict[str, Entry[T]] = {}
        self._loaded_builtins: set[str] = set()
        self._entry_points_loaded = False
        self._loading: str | None = None
        self._warned: set[tuple[str, str]] = set()

    # ------------------------------------------------------------------ registration
    def register(self, name: str, obj: T, *, replace: bool = False, source: str | None = None) -> T:
        """Add ``obj`` under ``name`` and return it.

        Registering the same object again is a no-op; a different object under a taken name
        needs ``replace=True``. An unavailable entry of that name is replaced.

        Raises:
            RegistrationError: empty name, or the name is taken and ``replace`` is False.
        """
        if not isinstance(name, str) or not name:
            raise RegistrationError(f"a {self.noun} needs a non-empty name, got {name!r}")
        old = self._entries.get(name)
        if old is not None and old.ok and not replace and not _same(old.obj, obj):
            raise RegistrationError(
                f"{self.noun} {name!r} is already registered (from {old.source})",
                hint="pick another name or pass replace=True",
            )
        src = source or self._loading
        if src is None:
            src = BUILTIN if self._module_of(obj).startswith("robogs.") else USER
        self._entries[name] = Entry(self.kind, name, obj, "ok", "", src)
        return obj

    def unregister(self, name: str) -> None:
        """Remove ``name`` (no error if absent)."""
        self._entries.pop(name, None)

    def mark_unavailable(self, name: str, reason: str, *, source: str = BUILTIN) -> None:
        """List ``name`` as unavailable (an optional dependency is missing); no warning.

        Ignored when ``name`` is already registered and usable.
        """
        old = self._entries.get(name)
        if old is None or not old.ok:
            self._entries[name] = Entry(self.kind, name, None, "unavailable", reason, source)

    def fail(self, name: str, reason: str, *, source: str) -> None:
        """Record a plug-in that failed to load: unavailable, with one :class:`PluginWarning`."""
        key = name
        old = self._entries.get(name)
        if old is not None and old.ok:  # never hide a working entry behind a broken one
            key = f"{name}@{source}"
        self._entries[key] = Entry(self.kind, key, None, "unavailable", reason, source)
        if (key, source) not in self._warned:
            self._warned.add((key, source))
            warnings.warn(
                f"{self.noun} plug-in {key!r} from {_origin(source)} is unavailable: {reason}",
                PluginWarning,
                stacklevel=3,
            )

    # ------------------------------------------------------------------ look-up
    def get(self, name: str) -> T:
        """The object registered as ``name``.

        Raises:
            PluginError: the entry is unavailable (names the plug-in, its source, the reason).
            InputError: no such name (the hint lists the usable ones).
        """
        self._load(name)
        entry = self._entries.get(name)
        if entry is None:
            raise InputError(
                f"unknown {self.noun} {name!r}",
                where=self._unknown_where,
                hint=f"choose from {', '.join(self.available()) or 'nothing registered'}",
            )
        if not entry.ok:
            raise PluginError(
                f"{self.noun} {name!r} from {_origin(entry.source)} is unavailable: {entry.reason}",
                hint=_fix_hint(entry.source),
            )
        return entry.obj  # type: ignore[return-value]

    def entries(self) -> list[Entry[T]]:
        """Every entry, usable or not, in listing order."""
        self._load()
        return sorted(self._entries.values(), key=self._order)

    def available(self) -> dict[str, T]:
        """``name -> object`` of the usable entries, in listing order."""
        return {e.name: e.obj for e in self.entries() if e.ok}  # type: ignore[misc]

    def __contains__(self, name: object) -> bool:
        self._load(name if isinstance(name, str) else None)
        return name in self._entries and self._entries[name].ok  # type: ignore[index]

    @contextmanager
    def sandbox(self) -> Iterator[Registry[T]]:
        """Within the block, entry points are read afresh (e.g. after installing a
        distribution in a test); on exit, every registration and load made inside is undone
        (entry points are read again on the next use if they had not been read before).

        Example:
            >>> from robogs.format.render.backends import REGISTRY
            >>> with REGISTRY.sandbox():
            ...     _ = REGISTRY.register("mine", lambda g, c, cfg: None)
            >>> "mine" in REGISTRY
            False
        """
        self._load_builtins(None)  # built-ins register once per process: keep them outside
        saved = (dict(self._entries), set(self._loaded_builtins), set(self._warned))
        loaded = self._entry_points_loaded
        self._entry_points_loaded = False
        try:
            yield self
        finally:
            self._entries, self._loaded_builtins, self._warned = saved
            self._entry_points_loaded = loaded

    # ------------------------------------------------------------------ loading
    @contextmanager
    def _as(self, source: str) -> Iterator[None]:
        before, self._loading = self._loading, source
        try:
            yield
        finally:
            self._loading = before

    def _import_builtin(self, module: str, names: Sequence[str]) -> None:
        if module in self._loaded_builtins:
            return
        self._loaded_builtins.add(module)
        try:
            with self._as(BUILTIN):
                importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name == module:  # an optional module that is not there: nothing to list
                return
            for name in names:
                self.mark_unavailable(name, f"{module} needs the package {exc.name!r}")
        except Exception as exc:  # a broken built-in is listed, never fatal
            for name in names:
                self.fail(name, f"{module} failed to import: {_why(exc)}", source=BUILTIN)

    def _load_builtins(self, name: str | None) -> None:
        if isinstance(self._builtins, Mapping):
            wanted = [name] if name is not None and name in self._builtins else list(self._builtins)
            for n in wanted:
                mod = self._builtins[n]
                self._import_builtin(mod, [k for k, m in self._builtins.items() if m == mod])
        else:
            for mod in self._builtins:
                self._import_builtin(mod, [mod.rsplit(".", 1)[-1]])

    def _load_entry_points(self) -> None:
        if self._entry_points_loaded:
            return
        self._entry_points_loaded = True
        try:
            eps = list(metadata.entry_points(group=self.group))
        except Exception as exc:  # broken distribution metadata must not stop robogs
            self.fail(self.group, f"listing the entry points failed: {_why(exc)}", source="?")
            return
        for ep in eps:
            dist = ep.dist.name if getattr(ep, "dist", None) is not None else "?"
            try:
                with self._as(dist):
                    self._adopt(self, ep.name, ep.load())
            except Exception as exc:  # a broken plug-in is listed, never fatal
                self.fail(ep.name, f"entry point {ep.value} failed: {_why(exc)}", source=dist)

    def _load(self, name: str | None = None) -> None:
        if self._loading is not None:  # a module being loaded asked for a listing
            return
        if name is None or name not in self._entries:
            self._load_builtins(name)
        self._load_entry_points()

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {self.group!r}, {len(self._entries)} entries)"


def _same(a: Any, b: Any) -> bool:
    if a is b:
        return True
    try:
        return bool(a == b)
    except Exception:  # objects whose == is not a bool (arrays) are different registrations
        return False


def _why(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def _origin(source: str) -> str:
    if source in (BUILTIN, USER):
        return "robogs" if source == BUILTIN else "user code"
    return f"distribution {source!r}"


def _fix_hint(source: str) -> str:
    if source == BUILTIN:
        return "install the missing dependency named in the reason"
    if source == USER:
        return "fix the code that registered it"
    return f"fix or uninstall {source} (pip uninstall {source})"
