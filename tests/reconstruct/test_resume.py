"""An interrupted reconstruction leaves the dataset untouched and resumes to the same result."""

from __future__ import annotations

import hashlib
from pathlib import Path
from shutil import copytree

import pytest
import torch

from robogs.format.dataset import Dataset
from robogs.format.errors import InputError
from robogs.reconstruct.densify import DensifyConfig
from robogs.reconstruct.pipeline import ReconstructOptions, reconstruct
from robogs.reconstruct.train import TrainConfig


def _options(work: Path) -> ReconstructOptions:
    # densify every 4 steps so the resumed run also depends on the checkpointed gradient sums;
    # log_every=1: on_step (which interrupts at step 7) is called after every step
    tc = TrainConfig(
        iterations=12,
        checkpoint_every=5,
        log_every=1,
        densify_from=0.0,
        densify_until=1.0,
        densify_every=4,
        densify=DensifyConfig(grad_threshold=1e-7),
    )
    return ReconstructOptions(
        train=tc, heldout_every=4, tsdf_resolution=40, work_dir=work, lr_scale=3.0, force=True
    )  # 6 training views of 48x36 px: below the coverage; 12 steps: below the floors


def _tree_digest(root: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file():
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()


class _Stop(Exception):
    pass


def test_interrupt_keeps_the_dataset_and_resume_matches_an_uninterrupted_run(
    tiny_capture: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    for d in (a, b, c):
        copytree(tiny_capture, d)
    before = _tree_digest(a)

    def stop_after_7(step: int, info: dict) -> None:
        if step == 7:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        reconstruct(a, _options(tmp_path / "work_a"), on_step=stop_after_7)
    assert _tree_digest(a) == before  # nothing written
    assert not list(tmp_path.glob(".a.*"))  # no temp folders or locks left in use
    ckpt = tmp_path / "work_a" / "checkpoint.pt"
    doc = torch.load(ckpt, weights_only=True)
    assert doc["iteration"] == 7

    resumed = reconstruct(a, _options(tmp_path / "work_a"))
    assert resumed.resumed_from == 7 and resumed.iterations == 12
    assert not ckpt.exists()  # removed after the successful commit
    fresh = reconstruct(b, _options(tmp_path / "work_b"))
    assert fresh.resumed_from == 0
    for rel in ("robot/splats.ply", "assets/box/splats.ply", "reconstruction/mesh.ply"):
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    assert Dataset.open(a).manifest["robot"]["splats"]["targets"] == ["base_link", "link1", "link2"]
    assert resumed.refinements == fresh.refinements  # the refinement counts are checkpointed

    # Ctrl-C after training (here: in the TSDF fusion) resumes without training again
    import robogs.reconstruct.pipeline as pipeline

    fuse = pipeline.fuse_tsdf

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "fuse_tsdf", interrupted)
    before = _tree_digest(c)
    with pytest.raises(KeyboardInterrupt):
        reconstruct(c, _options(tmp_path / "work_c"))
    assert _tree_digest(c) == before
    assert torch.load(tmp_path / "work_c" / "checkpoint.pt", weights_only=True)["iteration"] == 12
    monkeypatch.setattr(pipeline, "fuse_tsdf", fuse)
    steps: list[int] = []
    again = reconstruct(c, _options(tmp_path / "work_c"), on_step=lambda k, _: steps.append(k))
    assert again.resumed_from == 12 and not steps
    for rel in ("robot/splats.ply", "assets/box/splats.ply", "reconstruction/mesh.ply"):
        assert (c / rel).read_bytes() == (b / rel).read_bytes(), rel


def test_a_checkpoint_of_other_options_is_not_resumed(tiny_capture: Path, tmp_path: Path):
    ds = tmp_path / "ds"
    copytree(tiny_capture, ds)
    opts = _options(tmp_path / "work")

    def stop(step: int, info: dict) -> None:
        if step == 6:
            raise _Stop

    with pytest.raises(_Stop):
        reconstruct(ds, opts, on_step=stop)
    assert (tmp_path / "work" / "checkpoint.pt").exists()  # the periodic one, at step 5
    other = ReconstructOptions(
        **{**opts.__dict__, "train": TrainConfig(iterations=6, checkpoint_every=0)}
    )
    rep = reconstruct(ds, other)
    assert rep.resumed_from == 0 and rep.iterations == 6


def test_a_damaged_checkpoint_is_reported(tiny_capture: Path, tmp_path: Path):
    ds = tmp_path / "ds"
    copytree(tiny_capture, ds)
    work = tmp_path / "work"
    work.mkdir()
    (work / "checkpoint.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(InputError, match="checkpoint cannot be read"):
        reconstruct(ds, _options(work))
    rep = reconstruct(ds, ReconstructOptions(**{**_options(work).__dict__, "restart": True}))
    assert rep.iterations == 12
