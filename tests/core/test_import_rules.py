"""The dependency rules between the ``robogs`` subpackages, read from the source (issue 14).

Every ``import`` statement is parsed, including lazy ones inside functions and relative ones
(resolved against the module's package), so a rule cannot be broken by an import hidden in a
function body. ``importlib.import_module`` calls with a literal dotted name count too.

Rules:
- ``robogs.format`` imports no outer package (convert, physics, reconstruct, synth, cli);
- ``robogs.physics`` never imports ``robogs.convert`` (nor synth or cli);
- ``robogs.convert`` and ``robogs.reconstruct`` import only ``robogs.format``;
- ``robogs.synth`` never imports the renderer, the binding, the converters, the physics model
  or the reconstructor: the generators are independent of the code they test;
- no package imports ``robogs.cli`` except ``robogs.cli`` itself;
- no new code uses the deprecated top-level names.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2] / "robogs"
DEPRECATED = ("robogs_format", "converters", "reference_impl", "fixtures")


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, absolute dotted name) of every import in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    mod = _module_name(path)
    package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
    out: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            out.append((node.lineno, name))
            # ``from robogs import physics`` imports the subpackage
            out += [(node.lineno, f"{name}.{a.name}") for a in node.names if name == "robogs"]
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            out.append((node.lineno, node.args[0].value))
    return out


def _violations(package: str, forbidden: tuple[str, ...]) -> list[str]:
    bad = []
    for path in sorted((ROOT / package.removeprefix("robogs.").replace(".", "/")).rglob("*.py")):
        for line, name in _imports(path):
            if any(name == f or name.startswith(f + ".") for f in forbidden):
                bad.append(f"{path.relative_to(ROOT.parent)}:{line} imports {name}")
    return bad


OUTER = ("robogs.convert", "robogs.physics", "robogs.reconstruct", "robogs.synth", "robogs.cli")
RULES = {
    "robogs.format": OUTER,
    "robogs.physics": ("robogs.convert", "robogs.synth", "robogs.cli"),
    "robogs.reconstruct": ("robogs.convert", "robogs.physics", "robogs.synth", "robogs.cli"),
    "robogs.convert": ("robogs.physics", "robogs.reconstruct", "robogs.synth", "robogs.cli"),
    "robogs.synth": (
        "robogs.format.render",
        "robogs.format.rerender",
        "robogs.format.binding",
        "robogs.convert",
        "robogs.physics",
        "robogs.reconstruct",
        "robogs.cli",
    ),
}


@pytest.mark.parametrize("package", sorted(RULES))
def test_package_respects_its_import_rules(package: str) -> None:
    assert _violations(package, RULES[package]) == []


def test_no_module_uses_the_deprecated_names() -> None:
    bad = []
    for path in sorted(ROOT.rglob("*.py")):
        if path.name == "_compat.py":
            continue
        bad += [
            f"{path.relative_to(ROOT.parent)}:{line} imports {name}"
            for line, name in _imports(path)
            if name.split(".")[0] in DEPRECATED
        ]
    assert bad == []


def test_the_rules_catch_a_violation(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Mutation: a lazy relative import of physics from inside the format package is found."""
    fake = tmp_path / "robogs"
    (fake / "format" / "sub").mkdir(parents=True)
    (fake / "format" / "__init__.py").write_text("")
    (fake / "format" / "sub" / "__init__.py").write_text("")
    (fake / "format" / "sub" / "m.py").write_text(
        "def f():\n    from ...physics import model\n    return model\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "ROOT", fake)
    assert _violations("robogs.format", OUTER) == [
        "robogs/format/sub/m.py:2 imports robogs.physics"
    ]
