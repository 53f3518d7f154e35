"""Splat PLY files: the de-facto 3DGS layout plus robogs binding columns.

Layout (binary little-endian PLY, one ``vertex`` element, float32 unless noted):

* ``x y z`` — centre at the rest state, metres, world frame;
* ``nx ny nz`` — unused by 3DGS viewers, written as zeros;
* ``f_dc_0..2`` — SH degree-0 coefficients; ``f_rest_*`` — higher degrees,
  channel-major (all R coefficients, then G, then B), as in Kerbl et al. 2023;
* ``opacity`` — pre-sigmoid logit; ``scale_0..2`` (3DGS) or ``scale_0..1`` (2DGS) — log-scales, metres;
* ``rot_0..3`` — quaternion (w, x, y, z), not necessarily normalised;
* binding: ``bind_id`` (int32, index into the manifest's ``targets``), ``bind_face``
  (int32, face of the target's mesh, -1 if unbound), ``bind_u bind_v`` (barycentric
  weights of face vertices 1 and 2; vertex 0 gets 1-u-v), ``bind_offset`` (metres along
  the face normal).

Reading checks the header against the file size before allocating anything.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import FormatError

__all__ = ["SplatSet", "read_splat_ply", "write_splat_ply", "write_splat_arrays_ply", "MAX_SPLATS"]

MAX_SPLATS = 50_000_000
_MAX_HEADER = 64 * 1024
_PLY_TYPES = {
    "float": "<f4",
    "float32": "<f4",
    "double": "<f8",
    "float64": "<f8",
    "int": "<i4",
    "int32": "<i4",
    "uint": "<u4",
    "uint32": "<u4",
    "short": "<i2",
    "int16": "<i2",
    "ushort": "<u2",
    "uint16": "<u2",
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
}
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass
class SplatSet:
    """Gaussians at their rest state, with their binding.

    Attributes:
        means: [N, 3] metres, world frame at the rest state.
        quats: [N, 4] (w, x, y, z).
        log_scales: [N, 3] for 3DGS or [N, 2] for 2DGS, log of metres.
        opacity_logits: [N] pre-sigmoid.
        sh: [N, K, 3] SH coefficients, K in {1, 4, 9, 16}, DC first.
        bind_id: [N] int32 index into the owner's target list (-1: unbound).
        bind_face: [N] int32 face index in the target mesh (-1: none).
        bind_uv: [N, 2] barycentric weights of face vertices 1 and 2.
        bind_offset: [N] metres along the face normal.
    """

    means: np.ndarray
    quats: np.ndarray
    log_scales: np.ndarray
    opacity_logits: np.ndarray
    sh: np.ndarray
    bind_id: np.ndarray
    bind_face: np.ndarray
    bind_uv: np.ndarray
    bind_offset: np.ndarray

    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def kind(self) -> str:
        """'3dgs' or '2dgs' from the number of scales."""
        return "2dgs" if self.log_scales.shape[1] == 2 else "3dgs"

    @property
    def sh_degree(self) -> int:
        return int(round(self.sh.shape[1] ** 0.5)) - 1


def _parse_header(path: Path, head: bytes) -> tuple[int, int, list[tuple[str, str]]]:
    end = head.find(b"end_header\n")
    if not head.startswith(b"ply\n") or end < 0:
        raise FormatError(
            "not a PLY file or header longer than 64 KiB",
            path=path,
            where="header",
            hint="write splats in the binary little-endian 3DGS PLY layout",
        )
    lines = head[:end].decode("ascii", errors="replace").splitlines()
    body_start = end + len(b"end_header\n")
    count, props, fmt_ok, in_vertex, n_elements = -1, [], False, False, 0
    for no, line in enumerate(lines[1:], start=2):
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format":
            fmt_ok = tok[1:2] == ["binary_little_endian"]
        elif tok[0] == "element":
            n_elements += 1
            in_vertex = tok[1:2] == ["vertex"]
            if in_vertex:
                if len(tok) != 3 or not tok[2].isdigit():
                    raise FormatError(
                        "bad vertex element line", path=path, where=f"header line {no}"
                    )
                count = int(tok[2])
        elif tok[0] == "property" and in_vertex:
            if len(tok) != 3 or tok[1] not in _PLY_TYPES or not _NAME.match(tok[2]):
                raise FormatError(
                    f"unsupported property {line.strip()!r}",
                    path=path,
                    where=f"header line {no}",
                    hint="splat PLYs hold scalar properties only",
                )
            if any(tok[2] == name for name, _ in props):
                raise FormatError(
                    f"property {tok[2]!r} is declared twice",
                    path=path,
                    where=f"header line {no}",
                    hint="each splat column appears once",
                )
            props.append((tok[2], _PLY_TYPES[tok[1]]))
    if not fmt_ok:
        raise FormatError(
            "splat PLY must be binary_little_endian", path=path, where="header format line"
        )
    if count < 0 or n_elements != 1:
        raise FormatError(
            "splat PLY must have exactly one 'vertex' element", path=path, where="header"
        )
    if count > MAX_SPLATS:
        raise FormatError(
            f"header claims {count} Gaussians, over the limit of {MAX_SPLATS}",
            path=path,
            where="element vertex",
        )
    return count, body_start, props


def read_splat_ply(path: str | Path) -> SplatSet:
    """Read a 3DGS/2DGS splat PLY with optional binding columns.

    Raises:
        FormatError: bad header, size mismatch, missing columns or non-numeric data.
    """
    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.read(_MAX_HEADER)
    count, body_start, props = _parse_header(path, head)
    dtype = np.dtype(props)
    size = os.path.getsize(path)
    need = body_start + count * dtype.itemsize
    if size != need:
        raise FormatError(
            f"file has {size} bytes but its header implies {need} ({count} Gaussians x {dtype.itemsize} bytes)",
            path=path,
            where="body",
            hint="the file is truncated or its header is wrong; re-export it",
        )
    data = np.fromfile(path, dtype=dtype, count=count, offset=body_start)
    names = set(dtype.names or ())

    def cols(prefix: str) -> list[str]:
        found = sorted(
            (n for n in names if n.startswith(prefix) and n[len(prefix) :].isdigit()),
            key=lambda n: int(n[len(prefix) :]),
        )
        return found

    for req in (
        "x",
        "y",
        "z",
        "opacity",
        "f_dc_0",
        "f_dc_1",
        "f_dc_2",
        "rot_0",
        "rot_1",
        "rot_2",
        "rot_3",
    ):
        if req not in names:
            raise FormatError(
                f"missing column {req!r}",
                path=path,
                where="header",
                hint="splat PLYs follow the 3DGS layout (x y z f_dc_* f_rest_* opacity scale_* rot_*)",
            )
    scale_cols = cols("scale_")
    if len(scale_cols) not in (2, 3):
        raise FormatError(
            f"expected 2 (2DGS) or 3 (3DGS) scale columns, found {len(scale_cols)}",
            path=path,
            where="header",
        )
    rest = cols("f_rest_")
    if len(rest) % 3 or (len(rest) // 3 + 1) not in (1, 4, 9, 16):
        raise FormatError(
            f"{len(rest)} f_rest columns do not match an SH degree of 0..3",
            path=path,
            where="header",
        )
    k_rest = len(rest) // 3

    def stack(ns: list[str], dt: str = "<f4") -> np.ndarray:
        return (
            np.stack([data[n].astype(dt) for n in ns], axis=-1) if ns else np.zeros((count, 0), dt)
        )

    dc = stack(["f_dc_0", "f_dc_1", "f_dc_2"])[:, None, :]
    rest_arr = stack(rest).reshape(count, 3, k_rest).transpose(0, 2, 1)
    n = count
    return SplatSet(
        means=stack(["x", "y", "z"]),
        quats=stack(["rot_0", "rot_1", "rot_2", "rot_3"]),
        log_scales=stack(scale_cols),
        opacity_logits=data["opacity"].astype("<f4"),
        sh=np.concatenate([dc, rest_arr], axis=1),
        bind_id=data["bind_id"].astype("<i4") if "bind_id" in names else np.full(n, -1, "<i4"),
        bind_face=data["bind_face"].astype("<i4")
        if "bind_face" in names
        else np.full(n, -1, "<i4"),
        bind_uv=stack(["bind_u", "bind_v"])
        if {"bind_u", "bind_v"} <= names
        else np.zeros((n, 2), "<f4"),
        bind_offset=data["bind_offset"].astype("<f4")
        if "bind_offset" in names
        else np.zeros(n, "<f4"),
    )


_BIND_FIELDS = [
    ("bind_id", "<i4"),
    ("bind_face", "<i4"),
    ("bind_u", "<f4"),
    ("bind_v", "<f4"),
    ("bind_offset", "<f4"),
]


def write_splat_arrays_ply(
    path: str | Path,
    *,
    means: np.ndarray,
    quats: np.ndarray,
    log_scales: np.ndarray,
    opacity_logits: np.ndarray,
    sh: np.ndarray,
    binding: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None,
    comments: list[str],
) -> None:
    """The one 3DGS PLY writer: binary little-endian, float32 columns, int32 binding ids.

    Args:
        means: [N, 3] m; quats: [N, 4] (w, x, y, z) written as ``rot_0..3``;
        log_scales: [N, S] written as ``scale_0..S-1``; opacity_logits: [N];
        sh: [N, K, 3], ``f_rest_*`` channel-major as in the 3DGS reference layout;
        binding: ``(bind_id [N], bind_face [N], bind_uv [N, 2], bind_offset [N])`` or None;
        comments: header comment lines (without ``comment``).
    """
    n, k = sh.shape[0], sh.shape[1]
    fields = [(c, "<f4") for c in ("x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2")]
    fields += [(f"f_rest_{i}", "<f4") for i in range(3 * (k - 1))]
    fields += [("opacity", "<f4")]
    fields += [(f"scale_{i}", "<f4") for i in range(log_scales.shape[1])]
    fields += [(f"rot_{i}", "<f4") for i in range(4)]
    if binding is not None:
        fields += _BIND_FIELDS
    arr = np.zeros(n, dtype=np.dtype(fields))
    for i, c in enumerate("xyz"):
        arr[c] = means[:, i]
    for i in range(3):
        arr[f"f_dc_{i}"] = sh[:, 0, i]
    rest = sh[:, 1:, :].transpose(0, 2, 1).reshape(n, -1)  # channel-major
    for i in range(rest.shape[1]):
        arr[f"f_rest_{i}"] = rest[:, i]
    arr["opacity"] = opacity_logits
    for i in range(log_scales.shape[1]):
        arr[f"scale_{i}"] = log_scales[:, i]
    for i in range(4):
        arr[f"rot_{i}"] = quats[:, i]
    if binding is not None:
        bind_id, bind_face, bind_uv, bind_offset = binding
        arr["bind_id"] = bind_id
        arr["bind_face"] = bind_face
        arr["bind_u"] = bind_uv[:, 0]
        arr["bind_v"] = bind_uv[:, 1]
        arr["bind_offset"] = bind_offset
    inv = {"<f4": "float", "<i4": "int"}
    header = ["ply", "format binary_little_endian 1.0"]
    header += [f"comment {c}" for c in comments]
    header += [f"element vertex {n}"]
    header += [f"property {inv[t]} {name}" for name, t in fields]
    header += ["end_header"]
    with open(path, "wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        fh.write(arr.tobytes())


def write_splat_ply(path: str | Path, splats: SplatSet) -> None:
    """Write ``splats`` in the binary little-endian 3DGS layout with binding columns."""
    n = len(splats)
    k = splats.sh.shape[1]
    if k not in (1, 4, 9, 16) or splats.sh.shape != (n, k, 3):
        raise FormatError(
            f"sh must be [N, K, 3] with K in 1, 4, 9, 16; got {splats.sh.shape}", path=path
        )
    write_splat_arrays_ply(
        path,
        means=splats.means,
        quats=splats.quats,
        log_scales=splats.log_scales,
        opacity_logits=splats.opacity_logits,
        sh=splats.sh,
        binding=(splats.bind_id, splats.bind_face, splats.bind_uv, splats.bind_offset),
        comments=["robogs splats; rot_* is (w,x,y,z)"],
    )
