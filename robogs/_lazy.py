"""Lazy public names of a package (PEP 562 module ``__getattr__``).

A package lists ``name -> module`` and binds ``__getattr__ = lazy_getattr(__name__, TABLE)``:
the module is imported the first time the name is read, so importing the package stays cheap.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_getattr"]


def lazy_getattr(package: str, table: Mapping[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``package`` that reads ``name`` from ``table[name]``.

    Args:
        package: the dotted name of the package (its ``__name__``), for the error message.
        table: public name -> dotted name of the module that defines it.

    Returns:
        ``__getattr__(name)``; a name not in ``table`` raises ``AttributeError``, as for any
        module.
    """

    def __getattr__(name: str) -> Any:
        try:
            module = table[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        return getattr(importlib.import_module(module), name)

    return __getattr__
