"""Registry of render backends.

A backend is a function ``fn(gaussians, camera, config) -> RenderOutput`` that renders a pinhole
camera (``render`` handles lens distortion around it). Built-ins: ``torch`` (tiled, the default)
and ``dense`` (brute-force oracle). Third parties add theirs with :func:`register_backend` or an
entry point in the group ``robogs.backends`` whose object is such a function.
"""

from __future__ import annotations

from collections.abc import Callable
from importlib import metadata

from ..errors import RobogsError
from .camera import Camera
from .config import RenderConfig
from .gaussians import Gaussians
from .output import RenderOutput

__all__ = [
    "BackendFn",
    "register_backend",
    "available_backends",
    "get_backend",
    "ENTRY_POINT_GROUP",
]

BackendFn = Callable[[Gaussians, Camera, RenderConfig], RenderOutput]

ENTRY_POINT_GROUP = "robogs.backends"

_REGISTRY: dict[str, BackendFn] = {}
_UNAVAILABLE: dict[str, str] = {}
_entry_points_loaded = False


def register_backend(name: str, fn: BackendFn) -> None:
    """Add (or replace) the backend ``name``.

    Args:
        name: the key users pass as ``render(..., backend=name)``.
        fn: ``fn(gaussians, camera, config) -> RenderOutput`` rendering a pinhole camera.
    """
    if not isinstance(name, str) or not name:
        raise RobogsError(f"backend name must be a non-empty string, got {name!r}")
    if not callable(fn):
        raise RobogsError(f"backend {name!r} is not callable", hint="register a function")
    _REGISTRY[name] = fn
    _UNAVAILABLE.pop(name, None)


def mark_unavailable(name: str, reason: str) -> None:
    """Record that an optional backend could not be loaded, and why (with the install hint)."""
    if name not in _REGISTRY:
        _UNAVAILABLE[name] = reason


def _load_entry_points() -> None:
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in _REGISTRY:
            continue
        try:
            fn = ep.load()
        except Exception as exc:  # a broken plug-in must not break rendering
            mark_unavailable(ep.name, f"entry point {ep.value} failed to load: {exc}")
            continue
        if callable(fn):
            _REGISTRY[ep.name] = fn
        else:
            mark_unavailable(ep.name, f"entry point {ep.value} is not callable")


def available_backends() -> dict[str, str]:
    """Every known backend: name -> "ok", or the reason it is unavailable."""
    _load_entry_points()
    out = {name: "ok" for name in sorted(_REGISTRY)}
    out.update({name: why for name, why in sorted(_UNAVAILABLE.items()) if name not in _REGISTRY})
    return out


def get_backend(name: str) -> BackendFn:
    """The backend function registered as ``name``; raises with the reason if unavailable."""
    _load_entry_points()
    if name in _REGISTRY:
        return _REGISTRY[name]
    if name in _UNAVAILABLE:
        raise RobogsError(f"render backend {name!r} is unavailable: {_UNAVAILABLE[name]}")
    raise RobogsError(
        f"unknown render backend {name!r}",
        hint=f"available: {', '.join(sorted(_REGISTRY))}",
    )
