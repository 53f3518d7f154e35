"""Old import paths (``robogs_format``, ``converters``, ``reference_impl``, ``fixtures``).

Since 0.2 the code lives under the ``robogs`` namespace. The old top-level names keep working
for one minor version: importing one warns once (``DeprecationWarning``) and every module under
it is the *same object* as its new home, so classes and exceptions compare equal across both
spellings. They are removed in 0.3.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings
from types import ModuleType

__all__ = ["ALIASES", "install"]

#: old dotted prefix -> new dotted prefix (longest prefix wins)
ALIASES: dict[str, str] = {
    "robogs_format.cli": "robogs.cli",
    "robogs_format": "robogs.format",
    "converters": "robogs.convert",
    "reference_impl.physics": "robogs.physics",
    "reference_impl.reconstruct": "robogs.reconstruct",
    "fixtures.synth": "robogs.synth.scene",
    "fixtures": "robogs.synth",
}


def _target(name: str) -> str | None:
    for old in sorted(ALIASES, key=len, reverse=True):
        if name == old or name.startswith(old + "."):
            return ALIASES[old] + name[len(old) :]
    return None


class _AliasFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Resolve an old module name to the already-importable new module."""

    def find_spec(self, fullname, path=None, target=None):  # noqa: D401 - importlib protocol
        if fullname.partition(".")[0] not in {k.partition(".")[0] for k in ALIASES}:
            return None
        if "." not in fullname or _target(fullname) is None:
            return None  # the top-level shim packages load from disk and call install()
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec) -> ModuleType:
        return ModuleType(spec.name)  # placeholder, replaced in exec_module

    def exec_module(self, module: ModuleType) -> None:
        real = importlib.import_module(_target(module.__name__))  # type: ignore[arg-type]
        sys.modules[module.__name__] = real


_FINDER = _AliasFinder()


def install(old_top: str) -> ModuleType | None:
    """Called by a shim package ``old_top``: warn, register the finder, return the new module."""
    warnings.warn(
        f"'{old_top}' is deprecated since robogs 0.2 and will be removed in 0.3; "
        f"import from '{ALIASES[old_top] if old_top in ALIASES else 'robogs'}' instead",
        DeprecationWarning,
        stacklevel=3,
    )
    if _FINDER not in sys.meta_path:
        sys.meta_path.insert(0, _FINDER)
    new = ALIASES.get(old_top)
    return importlib.import_module(new) if new else None
