"""Find the folder of each ``package://NAME`` a URDF uses, the way ROS and yourdfpy do.

For each package name, in this order (the first hit wins):

1. ``--package NAME=DIR`` (``explicit``), then folders already known (a package shipped beside
   the source MCAP, :func:`robogs.convert.ingest.robot.sibling_packages`);
2. the URDF's ancestors (nearest first): a folder whose ``package.xml`` names ``NAME``, itself or
   its child ``NAME`` (how a catkin/colcon source tree is laid out);
3. the same ancestors, by folder name alone: the ancestor named ``NAME``, or its child ``NAME``;
4. ``ROS_PACKAGE_PATH`` (``os.pathsep``-separated), crawled like ``rospack``: an entry that is the
   package, or a ``package.xml`` naming ``NAME`` below it (at most :data:`MAX_DEPTH` levels, not
   descending into a package, skipping hidden folders);
5. yourdfpy's fallback (``filename_handler_magic``): the nearest ancestor ``A`` of the URDF for
   which ``A/<rest>`` is a file, ``<rest>`` being the URI after ``package://NAME/`` (the layout of
   pip-installed description packages such as ``example-robot-data``).

Every answer says how it was found, so the provenance can record where each mesh came from.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

__all__ = ["PackageRoot", "package_uris", "find_packages", "package_xml_name", "MAX_DEPTH"]

MAX_DEPTH = 6
_MAX_DIRS = 20_000
_MAX_ANCESTORS = 16
_URI = re.compile(r"package://([^/\s\"'<>]+)/([^\s\"'<>]+)")


@dataclass(frozen=True)
class PackageRoot:
    """Where ``package://name`` points: ``path`` (a folder) and ``how`` it was found."""

    name: str
    path: Path
    how: str

    def to_dict(self) -> dict[str, str]:
        return {"path": str(self.path), "how": self.how}


def package_xml_name(pkg_xml: Path) -> str | None:
    """The ``<name>`` of a ``package.xml`` (None when unreadable, over 1 MiB or without one)."""
    try:
        if pkg_xml.stat().st_size > 1 << 20:
            return None
        parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
        name = etree.parse(str(pkg_xml), parser).getroot().findtext("name")
    except (OSError, etree.XMLSyntaxError):
        return None
    return name.strip() if name else None


def package_uris(text: str) -> dict[str, list[str]]:
    """``package://NAME/rest`` URIs of a URDF text: name -> the ``rest`` parts, in order."""
    out: dict[str, list[str]] = {}
    for name, rest in _URI.findall(text):
        lst = out.setdefault(name, [])
        if rest not in lst:
            lst.append(rest)
    return out


def _ancestors(start: Path) -> list[Path]:
    start = start.resolve()
    return [start, *start.parents][:_MAX_ANCESTORS]


def _is_pkg(folder: Path, name: str) -> bool:
    return (folder / "package.xml").is_file() and package_xml_name(folder / "package.xml") == name


def _by_package_xml(name: str, starts: list[Path]) -> Path | None:
    for a in starts:
        for cand in (a, a / name):
            if _is_pkg(cand, name):
                return cand
    return None


def _by_folder_name(name: str, starts: list[Path]) -> Path | None:
    for a in starts:
        if a.name == name:
            return a
        if (a / name).is_dir():
            return a / name
    return None


def _crawl(name: str, entry: Path) -> Path | None:
    """A package ``name`` at or below ``entry`` (rospack's crawl, bounded)."""
    if _is_pkg(entry, name):
        return entry
    visited = 0
    for dirpath, dirnames, filenames in os.walk(entry, followlinks=False):
        here = Path(dirpath)
        visited += 1
        if visited > _MAX_DIRS:
            return None
        if "package.xml" in filenames and here != entry:
            dirnames[:] = []  # rospack does not look inside a package
            if package_xml_name(here / "package.xml") == name:
                return here
            continue
        if len(here.relative_to(entry).parts) >= MAX_DEPTH:
            dirnames[:] = []
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
    return None


def _by_env(name: str, env: str | None) -> Path | None:
    for item in (env or "").split(os.pathsep):
        if item.strip() and Path(item).is_dir():
            found = _crawl(name, Path(item).resolve())
            if found is not None:
                return found
    return None


def _by_rest(rests: list[str], starts: list[Path]) -> Path | None:
    if not rests:
        return None
    for a in starts:
        if (a / rests[0]).is_file():
            return a
    return None


def find_packages(
    uris: Mapping[str, Iterable[str]],
    search_from: Path | None,
    *,
    explicit: Mapping[str, str | os.PathLike[str]] | None = None,
    known: Mapping[str, PackageRoot] | None = None,
    env: str | None = None,
) -> dict[str, PackageRoot]:
    """The folder of each package name in ``uris`` (see the module docstring for the order).

    Args:
        uris: package name -> the URI parts after ``package://NAME/`` (``package_uris``).
        search_from: folder whose ancestors are searched (the URDF's folder); None: none.
        explicit: ``--package NAME=DIR`` folders (they win).
        known: folders found some other way (beside the source), used before the search.
        env: the ``ROS_PACKAGE_PATH`` value (default: the environment's).

    Returns:
        name -> :class:`PackageRoot` for the names found; names not found are left out (the
        caller says which mesh needs them).
    """
    env = os.environ.get("ROS_PACKAGE_PATH") if env is None else env
    starts = _ancestors(search_from) if search_from is not None else []
    out: dict[str, PackageRoot] = {}
    for name, rests in uris.items():
        rests = list(rests)
        if explicit and name in explicit:
            out[name] = PackageRoot(name, Path(explicit[name]), "--package")
            continue
        if known and name in known:
            out[name] = known[name]
            continue
        for how, find in (
            ("package.xml in a URDF ancestor", lambda n=name: _by_package_xml(n, starts)),
            ("folder name among the URDF's ancestors", lambda n=name: _by_folder_name(n, starts)),
            ("ROS_PACKAGE_PATH", lambda n=name: _by_env(n, env)),
            ("URDF ancestor holding the mesh path (yourdfpy)", lambda r=rests: _by_rest(r, starts)),
        ):
            path = find()
            if path is not None:
                out[name] = PackageRoot(name, path, how)
                break
    return out
