"""Training checkpoints: tensors and plain values only, loaded with ``torch.load(weights_only=True)``.

A checkpoint lives outside the dataset (the dataset changes only through the atomic writer at
the end of a run). It is written to ``<file>.part`` and renamed, so a crash while saving leaves
the previous checkpoint intact. ``fingerprint`` ties it to the inputs and options of a run: a
checkpoint with another fingerprint is never resumed.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch

from robogs.format.errors import InputError

__all__ = ["save_checkpoint", "load_checkpoint", "CHECKPOINT_FORMAT"]

CHECKPOINT_FORMAT = "robogs-reconstruct-checkpoint-1"


def save_checkpoint(
    path: Path,
    *,
    fingerprint: str,
    iteration: int,
    model_state: dict[str, Any],
    grad: torch.Tensor,
    count: torch.Tensor,
    psnr_history: list[float],
    refinements: list[dict[str, int]] | None = None,
) -> None:
    """Write a checkpoint atomically (``.part`` then rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {
        "format": CHECKPOINT_FORMAT,
        "fingerprint": fingerprint,
        "iteration": int(iteration),
        "model": model_state,
        "grad": grad.detach().cpu(),
        "count": count.detach().cpu(),
        "psnr_history": [float(x) for x in psnr_history],
        "refinements": [{k: int(v) for k, v in r.items()} for r in refinements or []],
    }
    part = path.with_name(path.name + ".part")
    torch.save(doc, part)
    os.replace(part, path)


def load_checkpoint(path: Path, fingerprint: str) -> dict[str, Any] | None:
    """The checkpoint at ``path`` if it belongs to this run (same fingerprint), else None.

    Raises:
        InputError: the file exists but is not a robogs checkpoint or cannot be read.
    """
    if not path.is_file():
        return None
    try:
        doc = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for damaged files
        raise InputError(
            f"checkpoint cannot be read ({type(exc).__name__})",
            path=path,
            hint="delete it or pass --restart to train from scratch",
        ) from None
    if not isinstance(doc, dict) or doc.get("format") != CHECKPOINT_FORMAT:
        raise InputError(
            "not a robogs reconstruction checkpoint",
            path=path,
            hint="delete it or pass --restart to train from scratch",
        )
    if doc.get("fingerprint") != fingerprint:
        return None
    return doc
