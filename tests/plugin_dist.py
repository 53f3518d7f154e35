"""Install a throwaway distribution (a module plus its ``dist-info``) into a site folder.

Used by the plug-in tests: with the folder on ``sys.path`` or ``PYTHONPATH``,
``importlib.metadata`` finds the distribution and its entry points exactly as it finds an
installed package.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

__all__ = ["write_dist"]


def write_dist(site: Path, dist: str, module: str, code: str, entry_points: str) -> Path:
    """Write module ``module`` (source ``code``) and the dist-info of ``dist`` into ``site``.

    Args:
        site: the site folder (created if needed).
        dist: distribution name, e.g. ``robogs-labplug``.
        module: top-level module name.
        code: module source (dedented).
        entry_points: ``entry_points.txt`` content, INI style (dedented).

    Returns:
        The dist-info folder.
    """
    site.mkdir(parents=True, exist_ok=True)
    (site / f"{module}.py").write_text(textwrap.dedent(code), encoding="utf-8")
    info = site / f"{dist.replace('-', '_')}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n", encoding="utf-8"
    )
    (info / "entry_points.txt").write_text(textwrap.dedent(entry_points), encoding="utf-8")
    files = [f"{module}.py"] + [f"{info.name}/{n}" for n in ("METADATA", "entry_points.txt")]
    (info / "RECORD").write_text(
        "".join(f"{f},,\n" for f in files) + f"{info.name}/RECORD,,\n", encoding="utf-8"
    )
    return info
