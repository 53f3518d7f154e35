"""``--device auto`` (the default of ``robogs reconstruct`` and ``evaluate``) picks the GPU only
when torch sees one."""

from __future__ import annotations

import torch

from robogs.cli import reconstruct_cmd


def test_auto_is_cuda_only_where_torch_sees_a_gpu(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert reconstruct_cmd.resolve_device("auto") == "cpu"
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert reconstruct_cmd.resolve_device("auto") == "cuda"
    assert reconstruct_cmd.resolve_device("cpu") == "cpu"
    assert reconstruct_cmd.resolve_device("cuda:1") == "cuda:1"


def test_the_default_is_auto():
    import argparse

    for verb in ("reconstruct", "evaluate"):
        p = argparse.ArgumentParser()
        reconstruct_cmd.add_arguments_for(verb, p)
        assert p.parse_args(["ds"]).device == "auto"
