"""The one registry shape (robogs.format.plugins), with real throwaway distributions.

A distribution is written as it would be installed: a module plus a ``dist-info`` folder
(METADATA, entry_points.txt, RECORD) in a temporary site directory put on ``sys.path``
(in-process tests) or ``PYTHONPATH`` (CLI tests in a subprocess). Nothing is monkeypatched.
"""

from __future__ import annotations

import importlib
import json
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from plugin_dist import write_dist

from robogs.format.errors import InputError
from robogs.format.plugins import (
    ENTRY_POINT_GROUPS,
    PluginError,
    PluginWarning,
    RegistrationError,
    Registry,
)

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent


# --------------------------------------------------------------------------- the helper


def test_register_get_entries_and_sources() -> None:
    reg: Registry[object] = Registry("things", "robogs.test-things-none", noun="thing")

    def twice(x: int) -> int:
        return 2 * x

    assert reg.register("twice", twice) is twice
    assert reg.register("twice", twice) is twice  # the same object again is a no-op
    with pytest.raises(RegistrationError, match="'twice' is already registered") as err:
        reg.register("twice", lambda x: 3 * x)
    assert isinstance(err.value, ValueError)
    reg.register("twice", abs, replace=True, source="mine")
    reg.register("len", len)  # defined outside robogs, outside an entry point
    reg.mark_unavailable("fast", "needs the optional package fastthing")
    reg.mark_unavailable("len", "ignored: a working entry is never hidden")
    assert [(e.name, e.status, e.source) for e in reg.entries()] == [
        ("fast", "unavailable", "builtin"),
        ("len", "ok", "user"),
        ("twice", "ok", "mine"),
    ]
    assert reg.available() == {"len": len, "twice": abs}
    assert reg.get("twice") is abs and "len" in reg and "fast" not in reg
    with pytest.raises(PluginError, match="thing 'fast' from robogs is unavailable: needs"):
        reg.get("fast")
    with pytest.raises(InputError, match="unknown thing 'nope'.*choose from len, twice"):
        reg.get("nope")
    with pytest.raises(RegistrationError):
        reg.register("", len)


def test_docstring_examples_run() -> None:
    import doctest

    from robogs.format import plugins

    result = doctest.testmod(plugins)
    assert result.attempted >= 8 and result.failed == 0


def test_builtins_load_lazily_and_per_name(tmp_path: Path, monkeypatch) -> None:
    log = tmp_path / "imported.txt"
    for name in ("lazy_a", "lazy_b"):
        (tmp_path / f"{name}.py").write_text(
            f"from pathlib import Path\n"
            f"Path({str(log)!r}).open('a').write('{name} ')\n"
            f"import builtins\nbuiltins._robogs_test_reg.register('{name[-1]}', len)\n"
        )
    (tmp_path / "lazy_bad.py").write_text("raise RuntimeError('disk on fire')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    reg: Registry[object] = Registry(
        "things",
        "robogs.test-things-none",
        noun="thing",
        builtins={"a": "lazy_a", "b": "lazy_b", "c": "lazy_bad", "d": "lazy_absent"},
    )
    monkeypatch.setattr("builtins._robogs_test_reg", reg, raising=False)
    assert not log.exists()  # nothing imported before the first look-up
    assert reg.get("a") is len and log.read_text() == "lazy_a "  # only the module asked for
    with pytest.warns(PluginWarning, match="thing plug-in 'c' from robogs is unavailable"):
        entries = {e.name: e for e in reg.entries()}
    assert log.read_text() == "lazy_a lazy_b "
    assert entries["a"].source == entries["b"].source == "builtin"
    assert entries["c"].status == "unavailable" and "disk on fire" in entries["c"].reason
    assert "d" not in entries  # an optional module that is not there lists nothing


CODE = """
    from dataclasses import dataclass, replace

    import pyarrow as pa

    from robogs.convert.registry import Converter
    from robogs.format.checks import check
    from robogs.physics.effects import Effect, Param


    @check("Z901", group="time", severity="warning", title="lab rule: episodes last >= 1 s",
           quantity="episode duration", unit="s", hint="record at least one second")
    def short_episode(chk, ctx):
        for ep in ctx.episodes:
            dur = (ep.end_ns - ep.start_ns) * 1e-9
            if dur < 1.0:
                yield chk.finding(f"episode lasts {dur:.3f} s", value=dur, budget=1.0,
                                  episode=ep.id)


    @dataclass(frozen=True)
    class LabDrag(Effect):
        name: str = "lab_drag"
        family: str = "contact"
        params: tuple = (Param("k", "1/s", 0.0, 5.0, 0.0, 0.5),)
        description: str = "the lab's drag"


    def detect(path):
        return path.suffix == ".labj"


    def convert(src, ctx):
        rows = [line.split() for line in src.read_text().splitlines() if line.strip()]
        t = [int(r[0]) for r in rows]
        table = pa.table({"t_ns": pa.array(t, pa.int64()),
                          "position.j1": pa.array([float(r[1]) for r in rows])})
        rel = f"{ctx.episode_dir()}/joint_states.parquet"
        ctx.writer.write_table(rel, table, kind="joint_states")
        ctx.add_stream("joint_states", {"kind": "joint_states", "path": rel,
                                        "stamp_source": "sidecar", "offset_ns": 0,
                                        "source": src.name}, start_ns=t[0], end_ns=t[-1])


    def render_shifted(gaussians, camera, config):
        from robogs.format.render.tiled import render_tiled
        return render_tiled(gaussians, camera, config)


    def render_wrong(gaussians, camera, config):
        out = render_shifted(gaussians, camera, config)
        return replace(out, rgb=out.rgb + 0.01)  # a bug the oracle comparison must catch


    LABJ = Converter("labj", detect, convert, "the lab joint log (.labj)")
"""

ENTRY_POINTS = """
    [robogs.checks]
    lab = labplug
    [robogs.effects]
    lab_drag = labplug:LabDrag
    [robogs.converters]
    labj = labplug:LABJ
    [robogs.backends]
    lab-tiled = labplug:render_shifted
    lab-wrong = labplug:render_wrong
"""

BROKEN = "raise ImportError('labstuff is not installed')\n"
BROKEN_EPS = """
    [robogs.checks]
    broken = brokenplug
    [robogs.backends]
    broken-backend = brokenplug:render
"""


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    site = tmp_path_factory.mktemp("site")
    write_dist(site, "robogs-labplug", "labplug", CODE, ENTRY_POINTS)
    write_dist(site, "robogs-brokenplug", "brokenplug", BROKEN, BROKEN_EPS)
    return site


def test_entry_points_of_a_real_distribution(site: Path, monkeypatch) -> None:
    from robogs.format.checks import registry as checks

    monkeypatch.syspath_prepend(str(site))
    importlib.invalidate_caches()
    for module in ("labplug", "brokenplug"):  # imported afresh here, forgotten afterwards
        monkeypatch.delitem(sys.modules, module, raising=False)
    reg: Registry[object] = Registry("backends", ENTRY_POINT_GROUPS["backends"], noun="backend")
    # importing labplug registers its check in the global registry: undo that afterwards
    with checks.REGISTRY.sandbox(), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first = {e.name: e for e in reg.entries()}
        again = {e.name: e for e in reg.entries()}
        with pytest.raises(PluginError) as err:
            reg.get("broken-backend")
    assert first == again
    assert first["lab-tiled"].source == "robogs-labplug" and first["lab-tiled"].ok
    broken = first["broken-backend"]
    assert (broken.status, broken.source) == ("unavailable", "robogs-brokenplug")
    assert "ImportError: labstuff is not installed" in broken.reason
    plugin_warnings = [w for w in caught if issubclass(w.category, PluginWarning)]
    assert len(plugin_warnings) == 1, [str(w.message) for w in caught]
    msg = err.value.one_line()
    assert "'broken-backend'" in msg and "robogs-brokenplug" in msg and "labstuff" in msg
    assert "pip uninstall robogs-brokenplug" in msg


# --------------------------------------------------------------------------- the CLI


def _robogs(site: Path, *args: str, script: str = "robogs") -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(site), "OMP_NUM_THREADS": "1"}
    return subprocess.run(
        [str(BIN / script), *args], capture_output=True, text=True, env=env, timeout=300
    )


def test_cli_lists_every_kind_with_status(site: Path) -> None:
    r = _robogs(site, "plugins", "--json")
    assert r.returncode == 0, r.stderr
    rows = {(e["kind"], e["name"]): e for e in json.loads(r.stdout)}
    ours = {k: v["source"] for k, v in rows.items() if v["source"] == "robogs-labplug"}
    assert ours == {
        ("checks", "Z901"): "robogs-labplug",
        ("effects", "lab_drag"): "robogs-labplug",
        ("converters", "labj"): "robogs-labplug",
        ("backends", "lab-tiled"): "robogs-labplug",
        ("backends", "lab-wrong"): "robogs-labplug",
    }
    assert rows[("effects", "joint_friction")]["status"] == "ok"  # arm effects, no import by hand
    assert rows[("checks", "T001")]["source"] == "builtin"
    for key in (("checks", "broken"), ("backends", "broken-backend")):
        assert rows[key]["status"] == "unavailable" and "labstuff" in rows[key]["reason"]
    # one warning per broken plug-in, on stderr, no traceback
    assert len(re.findall(r"PluginWarning", r.stderr)) == 2, r.stderr
    assert "Traceback" not in r.stderr


def test_cli_converts_and_validates_with_plugins(site: Path, tmp_path: Path) -> None:
    src = tmp_path / "run.labj"
    t0 = 1_700_000_000_000_000_000
    src.write_text("".join(f"{t0 + i * 10_000_000} {0.01 * i}\n" for i in range(51)))
    out = tmp_path / "ds"
    r = _robogs(site, "convert", str(src), str(out), "--from", "labj")
    assert r.returncode == 0, r.stderr
    r = _robogs(site, str(out), "--select", "Z901", "--json", script="robogs-validate")
    assert r.returncode in (0, 1), r.stderr
    found = [f for f in json.loads(r.stdout)["findings"] if f["code"] == "Z901"]
    assert len(found) == 1 and found[0]["value"] == pytest.approx(0.5)  # 50 steps of 10 ms
    # the broken check plug-in is reported as a finding, never fatal
    assert any(
        f["code"] == "X004" and "labstuff" in f["message"] for f in json.loads(r.stdout)["findings"]
    )


def test_cli_backend_renders_and_is_checked_against_the_oracle(site: Path) -> None:
    r = _robogs(site, "plugins", "--compare-backend", "lab-tiled", "--json")
    assert r.returncode == 0, r.stdout + r.stderr
    res = json.loads(r.stdout.splitlines()[-1])
    assert res["agrees"] and res["max_abs_rgb"] < 1e-6
    r = _robogs(site, "plugins", "--compare-backend", "lab-wrong", "--json")
    res = json.loads(r.stdout.splitlines()[-1])
    assert r.returncode == 1 and res["max_abs_rgb"] == pytest.approx(0.01, rel=1e-6)
    r = _robogs(site, "plugins", "--compare-backend", "broken-backend")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    (line,) = [ln for ln in r.stderr.splitlines() if "error:" in ln]
    assert "'broken-backend'" in line and "robogs-brokenplug" in line and "labstuff" in line


# --------------------------------------------------------------------------- the docs

DOCS = ROOT / "docs" / "plugins.md"


def test_groups_are_declared_and_documented() -> None:
    import tomllib

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]
    groups = set(ENTRY_POINT_GROUPS.values())
    assert {g for g in declared if g.startswith("robogs.")} == groups
    table = DOCS.read_text(encoding="utf-8").split("## A broken plug-in")[0]
    assert {g for g in groups if f"`{g}`" in table} == groups


def test_docs_examples_run(tmp_path: Path) -> None:
    blocks = re.findall(r"```python\n(.*?)```", DOCS.read_text(encoding="utf-8"), re.S)
    assert len(blocks) == 8
    driver = tmp_path / "run_docs.py"
    driver.write_text(
        "import json, sys\n"
        "ns = {'__name__': '__docs__'}\n"
        "for i, code in enumerate(json.loads(open(sys.argv[1]).read())):\n"
        "    exec(compile(code, f'docs/plugins.md python block {i + 1}', 'exec'), ns)\n"
        "print('ran', i + 1)\n"
    )
    (tmp_path / "blocks.json").write_text(json.dumps(blocks))
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    r = subprocess.run(
        [sys.executable, str(driver), str(tmp_path / "blocks.json")],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.split()[-2:] == ["ran", str(len(blocks))]


def test_layer_entry_points(tmp_path: Path, monkeypatch) -> None:
    from robogs.format.qa import rerun_log

    write_dist(
        tmp_path,
        "robogs-lablayer",
        "lablayer",
        "def note(ctx):\n    ctx.notes.append('lab layer ran')\n",
        "[robogs.layers]\nlab_note = lablayer:note\nbad = lablayer:missing_name\n",
    )
    with monkeypatch.context() as mp, rerun_log.REGISTRY.sandbox():
        mp.syspath_prepend(str(tmp_path))
        with pytest.warns(PluginWarning, match="'bad' from distribution 'robogs-lablayer'"):
            names = list(rerun_log.available_layers())
        assert names[: len(rerun_log.DEFAULT_LAYERS)] == list(rerun_log.DEFAULT_LAYERS)
        assert names[len(rerun_log.DEFAULT_LAYERS) :] == ["rerender", "lab_note"]
        entry = {e.name: e for e in rerun_log.layer_entries()}["lab_note"]
        assert (entry.status, entry.source) == ("ok", "robogs-lablayer")
        with pytest.raises(PluginError, match="missing_name"):
            rerun_log.REGISTRY.get("bad")
    assert "lab_note" not in rerun_log.available_layers()
