"""Suite-wide settings, and the one gate for tests that read the shared real-data folder.

The suite runs in two pytest-xdist workers on two cores; each worker's BLAS keeps to one thread,
otherwise the small dense solves in the physics fits contend for the cores and run several times
slower. Set before numpy is first imported in the worker.

Real data. Third-party robots, bags and calibrations live in ``../shared/fixtures/real`` beside
the checkout (``ROBOGS_REALDATA_DIR`` overrides the place). Tests that read it carry
``@pytest.mark.realdata`` and get the folder from the ``real_data`` fixture, never from a path
of their own. Where the folder is missing, those tests skip with one reason; with
``ROBOGS_REQUIRE_REALDATA=1`` (as in ``.ci/run``) they fail instead. A test that requests
``real_data`` (directly or through another fixture) without the marker fails.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # robogs --threads too
    os.environ.setdefault(_var, "1")

# Disk caches (refitted baselines, gate calibrations) go to a fresh folder per worker, never the
# user's ~/.cache/robogs: a calibration left there by another version must not decide a test.
os.environ["ROBOGS_CACHE_DIR"] = tempfile.mkdtemp(prefix="robogs-test-cache-")
# Design B's detectability (robogs.synth.scenarios.design_b: drive draws and plain fits, 10-30 s
# each) is memoised on disk in one folder per test run, shared by its xdist workers; the memo is
# keyed by the generator's inputs and source, and a fresh run starts empty.
_RUN = os.environ.get("PYTEST_XDIST_TESTRUNUID")
os.environ["ROBOGS_SYNTH_CACHE_DIR"] = (
    os.path.join(tempfile.gettempdir(), f"robogs-test-synth-{_RUN}")
    if _RUN
    else tempfile.mkdtemp(prefix="robogs-test-synth-")
)

REALDATA_DIR_ENV = "ROBOGS_REALDATA_DIR"
REQUIRE_REALDATA_ENV = "ROBOGS_REQUIRE_REALDATA"
_DEFAULT_REAL = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "real"


def real_data_dir() -> Path:
    """The real-data folder: ``$ROBOGS_REALDATA_DIR`` or ``../shared/fixtures/real``."""
    env = os.environ.get(REALDATA_DIR_ENV)
    return Path(env).expanduser().absolute() if env else _DEFAULT_REAL


def _require_real_data() -> Path:
    """The folder if present; else skip, or fail when ``ROBOGS_REQUIRE_REALDATA=1``."""
    path = real_data_dir()
    if path.is_dir():
        return path
    if os.environ.get(REQUIRE_REALDATA_ENV, "").strip().lower() in ("1", "true", "yes"):
        pytest.fail(
            f"../shared/fixtures/real not found at {path}, and {REQUIRE_REALDATA_ENV}=1 makes "
            f"this a failure; put the folder there or set {REALDATA_DIR_ENV} to it",
            pytrace=False,
        )
    pytest.skip(
        f"../shared/fixtures/real not found at {path}; "
        f"set {REQUIRE_REALDATA_ENV}=1 to make this a failure"
    )


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    marked = item.get_closest_marker("realdata") is not None
    if "real_data" in getattr(item, "fixturenames", ()) and not marked:
        pytest.fail(
            f"{item.nodeid} reads the real-data folder (fixture real_data) "
            "but is not marked @pytest.mark.realdata",
            pytrace=False,
        )
    if marked:
        _require_real_data()


@pytest.fixture(scope="session")
def real_data() -> Path:
    """The shared real-data folder (tests using it must be marked ``realdata``)."""
    return _require_real_data()


@pytest.fixture(scope="session")
def com_offset_fit(tmp_path_factory: pytest.TempPathFactory, worker_id: str) -> dict:
    """The hidden CoM offset's scenario fitted on the ``mujoco`` engine, once per session
    (:mod:`com_offset_fit`): ``{"path": the fitted dataset, read only, "fit": FitResult}``."""
    from com_offset_fit import com_offset_fit as run

    return run(tmp_path_factory.getbasetemp(), worker_id)
