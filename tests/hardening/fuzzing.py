"""Turn a fuzz target into a Hypothesis test that asserts the hardening contract.

``ROBOGS_FUZZ_EXAMPLES`` sets the number of examples per fuzz test (default 20, enough for
CI); ``bench/fuzz_campaign.py`` runs the same targets for much longer.
"""

from __future__ import annotations

import functools
import os

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from .seeds import Seeds
from .targets import run_case, target

__all__ = ["FUZZ_EXAMPLES", "fuzz_settings", "fuzz_test"]

FUZZ_EXAMPLES = int(os.environ.get("ROBOGS_FUZZ_EXAMPLES", "20"))

fuzz_settings = settings(
    max_examples=FUZZ_EXAMPLES,
    deadline=None,
    # the suite's run is reproducible (same examples every time); a campaign
    # (ROBOGS_FUZZ_EXAMPLES set) explores new ones
    derandomize="ROBOGS_FUZZ_EXAMPLES" not in os.environ,
    suppress_health_check=[
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
        HealthCheck.large_base_example,
    ],
)


@functools.cache
def _strategy(name: str, seeds: Seeds) -> st.SearchStrategy:
    return target(name).strategy(seeds)


def fuzz_test(name: str):
    """A test that runs the fuzz target ``name`` and asserts the contract on every case."""
    tgt = target(name)

    @fuzz_settings
    @given(data=st.data())
    def test(seeds: Seeds, data: st.DataObject) -> None:
        case = data.draw(_strategy(name, seeds), label=name)
        verdict = run_case(seeds, tgt, case)
        assert verdict.ok, f"{verdict.describe()}\ncase {case.variant}: {repr(case.data)[:1500]}"

    test.__name__ = f"test_fuzz_{name}"
    test.__doc__ = f"{tgt.family}: {tgt.inputs}."
    return test
