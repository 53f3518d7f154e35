"""Deliberate thread counts for every ``robogs`` verb (``--threads N``).

The problem it prevents is oversubscription. torch's intra-op pool is an OpenMP team, and
numpy/scipy's BLAS (OpenBLAS or MKL) keeps a pool of its own. Each library sizes its pool
once, when it is loaded, from the machine's cores. Without a setting, two such processes on
a 2-core machine run four or more busy threads on two cores.

OpenMP threads also spin-wait at the end of every parallel region before they sleep. The
physics rollouts run thousands of small regions, so a worker that waits burns the core its
partner needs, and every barrier waits for a thread that the scheduler has parked. That is
how a ``diagnose`` that takes about 40 s alone took 584 s beside another torch job (issue 13).

The fix has two parts:

* :func:`configure_env` runs in :mod:`robogs.cli.main` before numpy or torch is imported.
  It sets ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS`` and
  ``NUMBA_NUM_THREADS`` to N, so each pool is sized N from the start. It also sets
  ``OMP_WAIT_POLICY=PASSIVE`` (unless the user set it), so idle OpenMP threads sleep
  instead of spinning.
* :func:`applied` sets ``torch.set_num_threads(N)`` and, once per process,
  ``torch.set_num_interop_threads(N)``: at once if torch is loaded, else the moment a verb
  imports it (a one-shot import hook, so verbs that never need torch never pay for it).
  It puts the previous values back afterwards, so ``main([...])`` called inside a test
  leaves its process as it was.

N is resolved in this order: ``--threads``; then ``OMP_NUM_THREADS`` when the user exported
it; then the cores this process may use, ``len(os.sched_getaffinity(0))``. That last one
respects ``taskset`` and cgroup CPU sets, which ``os.cpu_count()`` ignores. Running several
jobs on one machine? Give each ``--threads`` so that the sum matches the cores.

This module imports neither numpy nor torch.
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import os
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

__all__ = [
    "ENV_VARS",
    "available_cores",
    "parse_threads",
    "resolve_threads",
    "configure_env",
    "restore_env",
    "apply_torch",
    "applied",
]

#: pool sizes read once, when each library loads
ENV_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
_WAIT = "OMP_WAIT_POLICY"
_NUMBA = "NUMBA_NUM_THREADS"
_interop_set: int | None = None


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity; ``os.cpu_count()`` where unknown)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - macOS, Windows
        return max(1, os.cpu_count() or 1)


def parse_threads(argv: Sequence[str]) -> int | None:
    """The value of ``--threads N`` or ``--threads=N`` anywhere in ``argv`` (None if absent).

    Raises:
        ValueError: the value is missing, not an integer, or below 1.
    """
    value: str | None = None
    for i, a in enumerate(argv):
        if a == "--":
            break
        if a == "--threads":
            if i + 1 >= len(argv):
                raise ValueError("--threads needs a value")
            value = argv[i + 1]
        elif a.startswith("--threads="):
            value = a.split("=", 1)[1]
    if value is None:
        return None
    try:
        n = int(value)
    except ValueError:
        raise ValueError(f"--threads must be an integer, got {value!r}") from None
    if n < 1:
        raise ValueError(f"--threads must be >= 1, got {n}")
    return n


def resolve_threads(requested: int | None) -> int:
    """``requested``, else a valid exported ``OMP_NUM_THREADS``, else :func:`available_cores`."""
    if requested is not None:
        return requested
    env = os.environ.get("OMP_NUM_THREADS", "")
    if env.isdigit() and int(env) >= 1:
        return int(env)
    return available_cores()


def configure_env(n: int) -> dict[str, str | None]:
    """Set the pool-size variables to ``n`` (and a passive OpenMP wait policy unless set).

    Takes effect for libraries not yet loaded and for child processes. Returns the previous
    values (None: unset) for :func:`restore_env`.
    """
    old: dict[str, str | None] = {k: os.environ.get(k) for k in (*ENV_VARS, _WAIT)}
    for k in ENV_VARS:
        if k == _NUMBA and "numba" in sys.modules:
            continue  # numba rereads it at every compilation: see restore_env
        os.environ[k] = str(n)
    os.environ.setdefault(_WAIT, "PASSIVE")
    return old


def restore_env(old: dict[str, str | None]) -> None:
    """Undo :func:`configure_env`, except ``NUMBA_NUM_THREADS`` once numba is loaded.

    numba reads its variables again before every compilation and raises if
    ``NUMBA_NUM_THREADS`` differs from the size of a thread pool it has started. So the
    variable keeps the value numba was loaded with, for the rest of the process, and
    :func:`configure_env` leaves it alone once numba is loaded (its parallel kernels take
    ``numba.set_num_threads`` instead: :mod:`robogs.format.render.fused`).
    """
    for k, v in old.items():
        if k == _NUMBA and "numba" in sys.modules:
            continue
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


def apply_torch(n: int) -> int | None:
    """Set torch's intra-op threads (and inter-op threads, once) to ``n`` if torch is loaded.

    Returns the previous intra-op count, or None when torch is not loaded.
    """
    global _interop_set
    torch = sys.modules.get("torch")
    if torch is None or not hasattr(torch, "set_num_threads"):
        return None
    prev = int(torch.get_num_threads())
    if prev != n:
        torch.set_num_threads(n)
    if _interop_set is None:
        try:  # allowed once per process, before any inter-op work
            if torch.get_num_interop_threads() != n:
                torch.set_num_interop_threads(n)
            _interop_set = n
        except RuntimeError:
            _interop_set = int(torch.get_num_interop_threads())
    return prev


class _TorchHook(importlib.abc.MetaPathFinder):
    """Calls :func:`apply_torch` right after ``import torch`` completes (one shot)."""

    def __init__(self, n: int) -> None:
        self.n = n

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if name != "torch":
            return None
        self.remove()
        spec = importlib.util.find_spec("torch")
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        run, n = spec.loader.exec_module, self.n

        def exec_module(module: Any) -> None:
            run(module)
            apply_torch(n)

        spec.loader.exec_module = exec_module  # type: ignore[method-assign]
        return spec

    def remove(self) -> None:
        if self in sys.meta_path:
            sys.meta_path.remove(self)


@contextmanager
def applied(n: int) -> Iterator[int]:
    """Run a block with ``n`` threads everywhere; the previous settings return afterwards."""
    old_env = configure_env(n)
    prev = apply_torch(n)
    hook = None
    if prev is None:
        hook = _TorchHook(n)
        sys.meta_path.insert(0, hook)
    try:
        yield n
    finally:
        if hook is not None:
            hook.remove()
        torch = sys.modules.get("torch")
        if torch is not None and hasattr(torch, "set_num_threads"):
            base = prev if prev is not None else _torch_default(old_env)
            if base is not None and torch.get_num_threads() != base:
                torch.set_num_threads(base)
        restore_env(old_env)


def _torch_default(old_env: dict[str, str | None]) -> int | None:
    """Torch loaded inside the block: the count it would have taken from the old environment."""
    v = old_env.get("OMP_NUM_THREADS")
    return int(v) if v is not None and v.isdigit() and int(v) >= 1 else None
