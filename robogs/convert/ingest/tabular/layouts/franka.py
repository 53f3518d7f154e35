"""Franka (libfranka ``RobotState``) logs.

Joints: ``q``/``dq`` by index (the generic families) and ``tau_J_i`` (measured link-side torque,
N m). End-effector: ``O_T_EE_0..15``, ``T_O_EE`` column by column, ``O`` the robot base (the URDF
root link). The link is the URDF's ``*hand_tcp`` (the end effector libfranka reports with a
Franka Hand), else, in a URDF without a hand, its ``*link8`` (the flange, the end effector with
no hand configured).
"""

from __future__ import annotations

import re

from ..pose import EePoseColumns

__all__ = ["JOINT_FAMILIES", "O_T_EE", "infer_o_t_ee"]

#: per-joint column families: (layout, kind, base name)
JOINT_FAMILIES = (("franka", "effort", "tau_J"),)
#: libfranka ``RobotState.O_T_EE``: the end-effector frame in the base frame ``O``, 4x4 column-major
O_T_EE = "O_T_EE"


def infer_o_t_ee(cols: dict[int, str], link_names: list[str]) -> tuple[EePoseColumns | None, str]:
    """``O_T_EE_0..15`` (``cols``: index -> column) as an ``ee_pose`` spec, with a sentence
    saying how it is read (or, when the spec is None, why it is not)."""
    if sorted(cols) != list(range(16)):
        return None, f"{O_T_EE}* ignored ({O_T_EE} needs 16 columns {O_T_EE}_0..15"
    tcp = [n for n in link_names if re.search(r"(^|_)hand_tcp$", n)]
    hands = [n for n in link_names if re.search(r"(^|_)hand$", n)]
    flange = [n for n in link_names if re.search(r"(^|_)link8$", n)]
    if len(tcp) == 1:
        link, why = tcp[0], "the hand's TCP link, libfranka's end effector with a Franka Hand"
    elif not hands and len(flange) == 1:
        link, why = flange[0], "the flange link, libfranka's end effector without a hand"
    else:
        return None, (
            f"{O_T_EE}* ignored (the URDF has no Franka end-effector link: one *hand_tcp, "
            "or *link8 without a hand"
        )
    spec = EePoseColumns(link, "matrix_colmajor", [cols[i] for i in range(16)])
    root = link_names[0] if link_names else "?"
    return spec, (
        f"{spec.columns[0]}..{spec.columns[-1]} read as the column-major 4x4 pose of link "
        f"{link!r} in the root link {root!r} (libfranka O_T_EE; link guessed: {why})"
    )
