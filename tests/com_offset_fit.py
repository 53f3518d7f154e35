"""The generator's hidden CoM offset fitted on the ``mujoco`` engine, once per test session (h98).

``tests/physics/test_mujoco_com_offset.py`` (the fit finds the hidden offset) and
``tests/converters/test_mjcf_export_body_effects.py`` (the exported body is the engine's model;
the export replays within the fit's residual) each ran the same fit: the ``com_offset``
scenario of seed 2 (nominal noise, its 9 centred and 4 off-centre pushes) written as a dataset
and ``robogs.physics.api.fit(path, ["com_offset"], engine="mujoco", mask_frames=0)``, about
40 s of CPU each. The fit is deterministic (one torch thread, as both ran it), so both now read
one run; ``write=True`` only adds the written revision to what ``write=False`` returns (the
physics test asserted on ``params`` and the RMS figures, which are the same).
"""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

__all__ = ["EFFECT", "KINDS", "SEED", "com_offset_fit", "run_fit"]

EFFECT = "com_offset"
SEED = 2
KINDS = ("push", "offset_push")


def run_fit(folder: Path) -> Any:
    """Write the scenario to ``folder / EFFECT`` and fit ``EFFECT`` on it (written); the
    :class:`robogs.physics.api.FitResult`."""
    import torch

    from robogs.physics import api
    from robogs.synth.scenarios import make_scenario, write_scenario

    torch.set_num_threads(1)
    rec = make_scenario(EFFECT, seed=SEED, kinds=KINDS, noise="nominal", check=False)
    path = folder / EFFECT
    write_scenario(rec, path)
    return api.fit(path, [EFFECT], engine="mujoco", mask_frames=0)


def com_offset_fit(basetemp: Path, worker_id: str) -> dict[str, Any]:
    """``{"path": the fitted dataset (read it, do not change it), "fit": its FitResult}``, the
    fit run once per session (:func:`session_once.once_per_session`; the FitResult pickled for
    the other workers, in this session's own temporary folder)."""
    from session_once import once_per_session

    folder, fit = once_per_session(
        "com_offset_fit", basetemp, worker_id, run_fit, pickle.dumps, pickle.loads
    )
    return {"path": folder / EFFECT, "fit": fit}
