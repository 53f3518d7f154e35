"""Registry of render backends.

A backend is a function ``fn(gaussians, camera, config) -> RenderOutput`` that renders a pinhole
camera (``render`` handles lens distortion around it). Built-ins: ``torch`` (tiled, the default)
and ``dense`` (brute-force oracle). Third parties add theirs with :func:`register_backend` or an
entry point in the group ``robogs.backends`` whose object is such a function. A backend whose
optional dependency is missing, or a plug-in that fails to load, is listed as unavailable with
the reason (:func:`backend_entries`) and raises a clear error when asked for.
"""

from __future__ import annotations

from collections.abc import Callable

from ..plugins import ENTRY_POINT_GROUPS, Entry, RegistrationError, Registry
from .camera import Camera
from .config import RenderConfig
from .gaussians import Gaussians
from .output import RenderOutput

__all__ = [
    "BackendFn",
    "register_backend",
    "available_backends",
    "backend_entries",
    "mark_unavailable",
    "REGISTRY",
    "get_backend",
    "ENTRY_POINT_GROUP",
]

BackendFn = Callable[[Gaussians, Camera, RenderConfig], RenderOutput]

ENTRY_POINT_GROUP = ENTRY_POINT_GROUPS["backends"]


def _adopt(reg: Registry[BackendFn], name: str, obj: object) -> None:
    """A ``robogs.backends`` entry point: the backend function, registered under its name."""
    if not callable(obj):
        raise TypeError(f"{type(obj).__name__} is not callable")
    register_backend(name, obj)  # type: ignore[arg-type]


#: the backend registry (built-ins are registered by ``robogs.format.render`` on import)
REGISTRY: Registry[BackendFn] = Registry(
    "backends",
    ENTRY_POINT_GROUP,
    noun="render backend",
    builtins=("robogs.format.render",),
    adopt=_adopt,
    unknown_where="backend",
)


def register_backend(name: str, fn: BackendFn, *, replace: bool = False) -> BackendFn:
    """Add the backend ``name`` and return ``fn``.

    Args:
        name: the key users pass as ``render(..., backend=name)``.
        fn: ``fn(gaussians, camera, config) -> RenderOutput`` rendering a pinhole camera.
        replace: allow replacing another backend of that name.

    Raises:
        RegistrationError: not callable, or the name is taken and ``replace`` is False.
    """
    if not callable(fn):
        raise RegistrationError(f"backend {name!r} is not callable", hint="register a function")
    return REGISTRY.register(name, fn, replace=replace)


def mark_unavailable(name: str, reason: str) -> None:
    """Record that an optional backend could not be loaded, and why (with the install hint)."""
    REGISTRY.mark_unavailable(name, reason)


def available_backends() -> dict[str, BackendFn]:
    """``name -> backend function`` of every usable backend, by name; :func:`backend_entries`
    also lists the unavailable ones (e.g. ``numba`` when it is not installed) with the reason."""
    return REGISTRY.available()


def backend_entries() -> list[Entry[BackendFn]]:
    """Every entry of the backend registry, usable or not, with status, reason and source."""
    return REGISTRY.entries()


def get_backend(name: str) -> BackendFn:
    """The backend function registered as ``name``.

    Raises:
        InputError: no such backend.
        PluginError: it is unavailable (the message says why).
    """
    return REGISTRY.get(name)
