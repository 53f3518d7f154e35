"""Small hidden-effect scenarios shared by the physics tests (cached per test process).

A uniquely named module rather than ``conftest``: several test folders have a conftest, so
``from conftest import ...`` resolves to whichever was imported first.
"""

from __future__ import annotations

import functools

from robogs.synth.scenarios import make_scenario


@functools.lru_cache(maxsize=16)
def scenario(
    effect: str, seed: int = 0, noise: str = "nominal", kinds: tuple[str, ...] = ("push",)
):
    """A 6-push scenario (2 speeds x 3 directions) unless ``kinds`` says otherwise."""
    return make_scenario(
        effect, seed=seed, noise=noise, kinds=kinds, n_speeds=2, n_dirs=3, check=False
    )
