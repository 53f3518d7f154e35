"""The wheel, installed without the source tree, synthesises and validates a scene.

Builds the wheel from a copy of the working tree (``pip wheel --no-deps
--no-build-isolation``), installs it into a fresh venv in a temp folder, and runs the
console scripts from a folder outside the checkout. The fresh venv gets its dependencies
from this project's venv through one plain path line in a ``.pth`` file: a plain line only
extends ``sys.path``, so the editable-install finder ``.pth`` of the project venv is not run
and ``import robogs`` can only come from the wheel.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest
from filelock import FileLock

REPO = Path(__file__).resolve().parents[2]
_SKIP = {".venv", ".git", "out", "build", "dist", "__pycache__", ".pytest_cache", ".ruff_cache",
         ".hypothesis"}  # fmt: skip

pytestmark = pytest.mark.slow


def _copy_source(dst: Path) -> Path:
    def ignore(_dir: str, names: list[str]) -> set[str]:
        return {n for n in names if n in _SKIP or n.endswith(".egg-info")}

    shutil.copytree(REPO, dst, symlinks=True, ignore=ignore)
    return dst


def _run(cmd: list[str], *, cwd: Path, env: dict[str, str], timeout: float):
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory, worker_id: str) -> dict:
    """Build the wheel, install it into a fresh venv; the paths and a clean environment.

    Under pytest-xdist the workers share one build (a folder of this test run, under a file
    lock), so the wheel is built once however the tests are spread.
    """
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(OMP_NUM_THREADS="1", PIP_NO_INPUT="1", PIP_DISABLE_PIP_VERSION_CHECK="1")
    if worker_id == "master":
        base = tmp_path_factory.mktemp("wheel")
        built = _build_and_install(base, env)
    else:  # the run's basetemp parent is shared by the workers of this run only
        base = tmp_path_factory.getbasetemp().parent / "wheel-shared"
        with FileLock(str(base) + ".lock"):
            built = (
                _build_and_install(base, env)
                if not (base / "installed").is_file()
                else _installed_paths(base)
            )
    work = tmp_path_factory.mktemp("work")  # outside the checkout, one per worker
    return {**built, "work": work, "env": env}


def _installed_paths(base: Path) -> dict:
    target = base / "venv"
    site = Path((base / "installed").read_text().strip())
    (wheel,) = sorted((base / "dist").glob("robogs-*.whl"))
    return {"wheel": wheel, "py": target / "bin" / "python", "bin": target / "bin", "site": site}


def _build_and_install(base: Path, env: dict[str, str]) -> dict:
    base.mkdir(parents=True, exist_ok=True)
    src = _copy_source(base / "src")
    res = _run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
         "-w", str(base / "dist"), str(src)],
        cwd=base, env=env, timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    wheels = sorted((base / "dist").glob("robogs-*.whl"))
    assert len(wheels) == 1, wheels

    target = base / "venv"
    venv.EnvBuilder(with_pip=True, clear=True).create(target)  # its own pip, as a user has
    py = target / "bin" / "python"
    site = Path(
        subprocess.check_output(
            [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            text=True, env=env,
        ).strip()
    )  # fmt: skip
    res = _run(
        [str(py), "-m", "pip", "install", "--no-deps", "--no-index", str(wheels[0])],
        cwd=base, env=env, timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    # the dependencies, from this venv's site-packages: one plain path line, no import line
    (site / "zz_robogs_test_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    (base / "installed").write_text(str(site) + "\n")
    return _installed_paths(base)


def test_the_wheel_ships_the_schemas_and_the_licence(installed: dict) -> None:
    names = zipfile.ZipFile(installed["wheel"]).namelist()
    want = sorted(p.name for p in (REPO / "robogs" / "format" / "schemas").glob("*.schema.json"))
    assert want, "no schemas in the source tree"
    got = sorted(
        n.rsplit("/", 1)[1]
        for n in names
        if n.startswith("robogs/format/schemas/") and n.endswith(".schema.json")
    )
    assert got == want
    assert any(n.split("/")[0].endswith(".dist-info") and n.endswith("/LICENSE") for n in names)
    assert not any(n.startswith(("tests/", "bench/")) for n in names)


def test_robogs_is_imported_from_the_wheel_and_reads_its_schemas(installed: dict) -> None:
    code = (
        "import robogs, robogs.format.schemas as s, robogs.format.spec_version as v;"
        "print(robogs.__file__); print(s.schema_dir()); print(v.SPEC_VERSION)"
    )
    res = _run([str(installed["py"]), "-c", code], cwd=installed["work"], env=installed["env"],
               timeout=300)  # fmt: skip
    assert res.returncode == 0, res.stderr
    mod, schemas, version = res.stdout.split()
    site = installed["site"].resolve()
    assert Path(mod).resolve().is_relative_to(site), mod
    assert not Path(mod).resolve().is_relative_to(REPO)
    assert Path(schemas).resolve() == site / "robogs" / "format" / "schemas"
    import robogs.format.spec_version as here

    assert version == here.SPEC_VERSION


def test_the_old_import_name_warns_and_works(installed: dict) -> None:
    code = (
        "import warnings\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    import robogs_format\n"
        "    from robogs_format import Dataset\n"
        "print(sum(issubclass(x.category, DeprecationWarning) for x in w))\n"
        "import robogs.format\n"
        "print(Dataset is robogs.format.Dataset)\n"
        "print(robogs_format.__file__ if hasattr(robogs_format, '__file__') else '')\n"
    )
    res = _run([str(installed["py"]), "-c", code], cwd=installed["work"], env=installed["env"],
               timeout=300)  # fmt: skip
    assert res.returncode == 0, res.stderr
    n_warn, same, *_ = res.stdout.split("\n")
    assert int(n_warn) >= 1 and same == "True", res.stdout


def test_synth_and_validate_from_the_installed_scripts(installed: dict) -> None:
    work, env, bin_ = installed["work"], installed["env"], installed["bin"]
    (work / "out").mkdir(exist_ok=True)  # as the README tour does
    res = _run([str(bin_ / "robogs"), "synth", "out/s", "--size", "small"], cwd=work, env=env,
               timeout=600)  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    assert (work / "out" / "s" / "manifest.json").is_file()
    res = _run([str(bin_ / "robogs-validate"), "out/s"], cwd=work, env=env, timeout=600)
    text = res.stdout + res.stderr
    assert "schemas are missing" not in text and "Traceback" not in text, text[-3000:]
    assert res.returncode == 0, text[-3000:]
    assert not any(p.name.endswith(".lock") for p in (work / "out").iterdir())


def test_the_demo_runs_from_the_installed_script(installed: dict) -> None:
    """The README's main job, from the wheel (about 2 min on 2 cores)."""
    work = installed["work"]
    res = _run([str(installed["bin"] / "robogs"), "demo", "out/demo", "--no-progress"],
               cwd=work, env=installed["env"], timeout=900)  # fmt: skip
    text = res.stdout + res.stderr
    assert res.returncode == 0, text[-3000:]
    assert "schemas are missing" not in text and "Traceback" not in text, text[-3000:]
    for name in ("report.html", "physics_report.html"):
        assert (work / "out" / "demo" / name).is_file(), name
    assert not [p for p in (work / "out").rglob(".*.lock")]  # every writer removed its lock
