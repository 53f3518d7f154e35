"""Findings: what a validation check reports, as plain data.

A :class:`Finding` is never an exception. It names the check code, a severity,
where the problem is (:class:`Location`), the measured value against its budget
(with the unit), a one-sentence message and a hint for the fix. The pass/fail
policy (``--fail-on``) is applied afterwards, by the caller.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

__all__ = [
    "Severity",
    "SEVERITIES",
    "severity_rank",
    "Location",
    "Finding",
]

Severity = Literal["error", "warning", "info"]

#: severities from most to least severe
SEVERITIES: tuple[str, ...] = ("error", "warning", "info")


def severity_rank(severity: str) -> int:
    """0 for error, 1 for warning, 2 for info (lower is more severe).

    Raises:
        ValueError: an unknown severity name.
    """
    try:
        return SEVERITIES.index(severity)
    except ValueError:
        raise ValueError(f"unknown severity {severity!r}; use one of {SEVERITIES}") from None


@dataclass(frozen=True)
class Location:
    """Where a finding is. Every field is optional; set the ones that apply.

    Attributes:
        file: dataset-relative path (``/``-separated) of the file concerned.
        where: the place inside the file: a JSON pointer, ``row 17``, a column, a URDF element.
        episode: episode id.
        stream: stream name as in the manifest (e.g. ``joint_states``, ``camera/cam0``).
        frame: camera frame index.
        t_ns: stamp on the dataset clock, ns.
        link: robot link or joint name.
        object: object or asset name.
    """

    file: str | None = None
    where: str | None = None
    episode: str | None = None
    stream: str | None = None
    frame: int | None = None
    t_ns: int | None = None
    link: str | None = None
    object: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The fields that are set (others left out)."""
        return {k: v for k, v in asdict(self).items() if v is not None}

    def __str__(self) -> str:
        parts: list[str] = []
        if self.file:
            parts.append(self.file + (f" {self.where}" if self.where else ""))
        elif self.where:
            parts.append(self.where)
        for key in ("episode", "stream", "link", "object", "frame"):
            value = getattr(self, key)
            if value is not None:
                parts.append(f"{key} {value}")
        if self.t_ns is not None:
            parts.append(f"t_ns {self.t_ns}")
        return ", ".join(parts) if parts else "dataset"


@dataclass(frozen=True)
class Finding:
    """One reported problem (or observation).

    Attributes:
        code: stable check code, e.g. ``T003``.
        severity: ``error``, ``warning`` or ``info``.
        message: what was found, in one sentence.
        location: where.
        value: the measured quantity (``None`` when not a number), in ``unit``.
        budget: the allowed value of ``value`` (``None`` when not budgeted), in ``unit``.
        unit: unit of ``value`` and ``budget`` (``mm``, ``ms``, ``px``, ``rad``, ...).
        hint: how to fix it.
    """

    code: str
    severity: Severity
    message: str
    location: Location = field(default_factory=Location)
    value: float | None = None
    budget: float | None = None
    unit: str = ""
    hint: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict; non-finite values become strings (``"inf"``, ``"nan"``)."""
        return {
            "code": self.code,
            "severity": self.severity,
            "location": self.location.to_dict(),
            "value": _json_number(self.value),
            "budget": _json_number(self.budget),
            "unit": self.unit,
            "message": self.message,
            "hint": self.hint,
        }

    def value_text(self) -> str:
        """``value unit (budget b unit)`` for humans, or an empty string."""
        if self.value is None:
            return ""
        text = f"{_fmt(self.value)} {self.unit}".strip()
        if self.budget is not None:
            text += f" (budget {_fmt(self.budget)} {self.unit})".replace(" )", ")")
        return text


def _json_number(x: float | None) -> float | str | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else str(x)


def _fmt(x: float) -> str:
    if not math.isfinite(x):
        return str(x)
    if x == int(x) and abs(x) < 1e15:
        return str(int(x))
    return f"{x:.4g}"
