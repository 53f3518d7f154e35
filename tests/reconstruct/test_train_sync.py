"""The training step leaves the device alone: no host copy per step, PSNRs gathered every
``log_every`` steps in one transfer, the backend resolved once (issue 23)."""

from __future__ import annotations

import importlib
import inspect
import math
import sys
import warnings
from pathlib import Path

import pytest
import torch

from robogs.format.errors import RobogsError
from robogs.format.render import Camera, available_backends
from robogs.reconstruct.densify import DensifyConfig, GradientStats
from robogs.reconstruct.image_metrics import psnr
from robogs.reconstruct.train import TrainConfig, resolve_backend, train
from robogs.reconstruct.views import View

# the module, not the function ``robogs.reconstruct.train`` that the package exports
train_mod = importlib.import_module("robogs.reconstruct.train")
#: the modules of the training step; a host copy made from one of them is counted
_STEP_MODULES = (
    "train.py",
    "losses.py",
    "densify.py",
    "model.py",
    "image_metrics.py",
    "step_loss.py",
)
_RECONSTRUCT = str(Path(train_mod.__file__).parent)
#: Tensor methods that copy a value to the host (and so wait for the device)
_HOST_COPIES = ("item", "tolist", "cpu", "numpy", "__float__", "__int__", "__bool__", "__index__")


def _scene(n_views: int = 3, device: str = "cpu"):
    cam = Camera(
        width=16, height=12, fx=14.0, fy=14.0, cx=8.0, cy=6.0,
        T_world_cam=torch.eye(4, dtype=torch.float64),
    )  # fmt: skip
    target = torch.zeros(12, 16, 3)
    target[:, :8] = torch.tensor([0.8, 0.2, 0.1])
    views = [View(f"c/{i}", "c", i, i, cam, target, None) for i in range(n_views)]
    g = torch.Generator().manual_seed(0)
    n = 12
    init = {
        "means": torch.randn(n, 3, generator=g) * 0.1 + torch.tensor([0.0, 0.0, 1.0]),
        "quats": torch.randn(n, 4, generator=g),
        "log_scales": torch.full((n, 2), math.log(0.05)),
        "opacity_logits": torch.zeros(n),
        "sh_dc": torch.randn(n, 1, 3, generator=g),
        "sh_rest": torch.zeros(n, 0, 3),
    }
    return views, {k: v.to(device) for k, v in init.items()}


def _cfg(steps: int, log_every: int, **kw) -> TrainConfig:
    # every loss term from step 0, gradient statistics every step, no refinement in the run
    base = dict(
        iterations=steps,
        log_every=log_every,
        checkpoint_every=0,
        dist_from=0.0,
        normal_from=0.0,
        densify_from=0.0,
        densify_until=1.0,
        densify_every=10_000,
        opacity_reset_every=0,
    )
    return TrainConfig(**{**base, **kw})


class _HostCopyCounter:
    """Counts the host copies (``_HOST_COPIES``) called from the training step's modules."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.calls: list[tuple[str, str, str]] = []
        for name in _HOST_COPIES:
            monkeypatch.setattr(torch.Tensor, name, self._wrap(name, getattr(torch.Tensor, name)))

    def _wrap(self, name: str, fn):
        def counted(t, *a, **kw):
            f = sys._getframe(1)
            path = f.f_code.co_filename
            if path.startswith(_RECONSTRUCT) and path.endswith(_STEP_MODULES):
                # _view_at works on a CPU generator's CPU tensors by construction
                if f.f_code.co_name != "_view_at":
                    self.calls.append((name, Path(path).name, f.f_code.co_name))
            return fn(t, *a, **kw)

        return counted


@pytest.mark.parametrize("steps", [6, 7])
def test_one_host_copy_per_log_interval_not_per_step(steps: int, monkeypatch):
    views, init = _scene()
    gathers: list[int] = []
    real_gather = train_mod._gather

    def gather(buf):
        gathers.append(len(buf))
        return real_gather(buf)

    monkeypatch.setattr(train_mod, "_gather", gather)
    logged: list[tuple[int, float]] = []
    counter = _HostCopyCounter(monkeypatch)
    res = train(
        views,
        init,
        _cfg(steps, 3),
        extent=1.0,
        on_step=lambda k, info: logged.append((k, info["psnr"])),
    )
    monkeypatch.undo()
    want = math.ceil(steps / 3)
    # the only host copies of the step's modules are the gathers' tolist, one per interval
    assert counter.calls == [("tolist", "train.py", "_gather")] * want
    assert gathers == [3, 3, 1][:want]
    assert len(res.psnr_history) == steps
    ends = [3, 6, 7][:want]
    assert logged == [(k, res.psnr_history[k - 1]) for k in ends]


def test_log_every_changes_nothing_but_when_the_psnr_is_read():
    views, init = _scene()
    a = train(views, init, _cfg(7, 1), extent=1.0)
    b = train(views, init, _cfg(7, 4), extent=1.0)
    assert a.psnr_history == b.psnr_history
    for k in a.model.params:
        assert torch.equal(a.model.params[k], b.model.params[k]), k


def test_the_step_psnr_matches_image_metrics():
    g = torch.Generator().manual_seed(3)
    x, y = torch.rand(12, 16, 3, generator=g), torch.rand(12, 16, 3, generator=g)
    assert float(train_mod._psnr_on_device(x, y)) == pytest.approx(psnr(x, y), abs=1e-10)
    assert float(train_mod._psnr_on_device(x, x)) == 99.0  # inf -> 99, as before
    nan = x.clone()
    nan[0, 0, 0] = float("nan")
    assert float(train_mod._psnr_on_device(nan, y)) == 99.0


class _Stop(KeyboardInterrupt):
    pass


def test_interrupt_between_log_points_resumes_to_the_same_run(tmp_path: Path):
    """Ctrl-C at a log point with buffered PSNRs: the checkpoint holds all of them, and the
    resumed run ends with the history and Gaussians of an uninterrupted one."""
    views, init = _scene()
    cfg = _cfg(8, 2, densify_every=3, densify=DensifyConfig(grad_threshold=1e-9))
    ckpt = tmp_path / "c.pt"

    def stop(k: int, info: dict) -> None:
        if k == 4:
            raise _Stop

    with pytest.raises(_Stop):
        train(views, init, cfg, extent=1.0, checkpoint=ckpt, on_step=stop)
    doc = torch.load(ckpt, weights_only=True)
    assert doc["iteration"] == 4 and len(doc["psnr_history"]) == 4
    resumed = train(views, init, cfg, extent=1.0, checkpoint=ckpt)
    fresh = train(views, init, cfg, extent=1.0)
    assert resumed.resumed_from == 4 and resumed.iterations == 8
    assert resumed.psnr_history == fresh.psnr_history and len(fresh.psnr_history) == 8
    assert resumed.refinements == fresh.refinements and fresh.refinements  # refined at 3 and 6
    for k in fresh.model.params:
        assert torch.equal(resumed.model.params[k], fresh.model.params[k]), k


def test_backend_is_resolved_once_and_passed_to_every_render(monkeypatch):
    views, init = _scene()
    seen: list[str] = []
    real_render = train_mod.render

    def render(g, cam, *, config, backend):
        seen.append(backend)
        return real_render(g, cam, config=config, backend="torch")

    monkeypatch.setattr(train_mod, "render", render)
    train(views, init, _cfg(3, 50), extent=1.0)
    assert seen == ["torch"] * 3  # auto on the CPU
    seen.clear()
    train(views, init, _cfg(3, 50, backend="dense"), extent=1.0)
    assert seen == ["dense"] * 3
    with pytest.raises(RobogsError, match="no-such-backend"):
        train(views, init, _cfg(3, 50, backend="no-such-backend"), extent=1.0)
    with pytest.raises(RobogsError, match="log_every"):
        train(views, init, _cfg(3, 0), extent=1.0)


def test_auto_picks_triton_only_on_cuda_where_it_is_available(monkeypatch):
    both = {"torch": object(), "triton": object()}
    monkeypatch.setattr(train_mod, "available_backends", lambda: both)
    assert resolve_backend("auto", "cuda") == "triton"
    assert resolve_backend("auto", torch.device("cuda", 1)) == "triton"
    assert resolve_backend("auto", "cpu") == "torch"
    monkeypatch.setattr(train_mod, "available_backends", lambda: {"torch": object()})
    assert resolve_backend("auto", "cuda") == "torch"
    assert resolve_backend("torch", "cuda") == "torch"


def test_gradient_stats_scale_matches_the_ndc_norm():
    s = GradientStats(3, torch.device("cpu"))
    g = torch.tensor([[3e-3, 4e-3], [1.0, 1.0], [0.0, 2e-3]], dtype=torch.float64)
    radii = torch.tensor([[1, 1], [0, 0], [2, 0]])
    s.add(g, radii, width=20, height=10)
    want = [math.hypot(3e-3 * 10, 4e-3 * 5), 0.0, 2e-3 * 5]
    assert s.grad.tolist() == pytest.approx(want, rel=1e-12)
    assert s.count.tolist() == [1.0, 0.0, 1.0]


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("backend", ["torch", "triton"])
def test_on_cuda_the_step_modules_never_wait_for_the_device(backend: str):
    """CUDA's sync debug mode flags every synchronising call (``.item()``, ``.tolist()``, a
    pageable host-to-device copy, ``nonzero``). From the step's own modules only the gathers
    (one per ``log_every`` steps) and the moves of the views before the loop (at most two per
    view) may sync: a sync per step would flag at least ``steps`` more. The renderer's own
    syncs (tile binning) are not counted here."""
    if backend not in available_backends():
        pytest.skip(f"backend {backend!r} unavailable here")
    views, init = _scene(device="cuda")  # the views stay on the host: train moves them
    steps, every = 12, 4
    train(views, init, _cfg(2, 1, backend=backend), extent=1.0)  # compile kernels, fill caches
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        torch.cuda.set_sync_debug_mode("warn")
        try:
            res = train(views, init, _cfg(steps, every, backend=backend), extent=1.0)
        finally:
            torch.cuda.set_sync_debug_mode(0)
    ours = [
        (Path(w.filename).name, w.lineno)
        for w in caught
        if "synchroniz" in str(w.message)
        and w.filename.startswith(_RECONSTRUCT)
        and w.filename.endswith(_STEP_MODULES)
    ]
    src, first = inspect.getsourcelines(train_mod._gather)
    in_gather = [n for n in ours if n[0] == "train.py" and first <= n[1] < first + len(src)]
    others = [n for n in ours if n not in in_gather]
    assert len(in_gather) == steps // every, ours
    assert len(others) <= 2 * len(views), others
    assert len(res.psnr_history) == steps
    assert res.model.params["means"].device.type == "cuda"


def test_the_pipeline_and_cli_pass_device_and_backend_through(
    tiny_capture: Path, tmp_path: Path, monkeypatch, capsys
):
    from robogs.cli.main import main
    from robogs.reconstruct import pipeline
    from robogs.reconstruct.pipeline import ReconstructOptions, reconstruct

    seen: dict = {}

    class _Seen(Exception):
        pass

    def fake_train(views, init, cfg, **kw):
        seen.update(backend=cfg.backend, log_every=cfg.log_every, device=init["means"].device)
        raise _Seen

    monkeypatch.setattr(pipeline, "train", fake_train)
    opts = ReconstructOptions(
        train=TrainConfig(iterations=3, backend="dense", log_every=7),
        heldout_every=4,
        work_dir=tmp_path / "w",
        force=True,
    )
    with pytest.raises(_Seen):
        reconstruct(tiny_capture, opts)
    assert seen == {"backend": "dense", "log_every": 7, "device": torch.device("cpu")}
    seen.clear()
    args = ["reconstruct", str(tiny_capture), "--no-progress", "--force", "--heldout-every", "4"]
    args += ["--work-dir", str(tmp_path / "w2"), "--backend", "torch", "--log-every", "9"]
    with pytest.raises(_Seen):
        main(args)
    # the CLI's --device defaults to auto: the GPU where there is one (the API's default is the CPU)
    auto = "cuda" if torch.cuda.is_available() else "cpu"
    assert seen.pop("device").type == auto
    assert seen == {"backend": "torch", "log_every": 9}
    # an unknown backend: one clear line and exit code 2, before any training
    seen.clear()
    code = main([*args[:-4], "--backend", "no-such-backend"])
    assert code == 2 and not seen
    assert "no-such-backend" in capsys.readouterr().err
