"""The arm physics loop from the command line: compare names worst phases, diagnose and fit print,
held-out split per trajectory, held (unlogged) joints, a log without efforts."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robogs.cli.main import main
from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.convert.ingest.tabular import TabularOptions
from robogs.format.dataset import Dataset
from robogs.physics.arm import compare_arm
from robogs.synth.armlogs import ArmLogSpec, generate_armlog, ur5_urdf


def _reversal_rows(qd: np.ndarray, t: np.ndarray, half_s: float) -> np.ndarray:
    """Rows within ``half_s`` of a sign change of ``qd`` (brute force over all pairs)."""
    flips = t[1:][np.sign(qd[1:]) * np.sign(qd[:-1]) < 0]
    if len(flips) == 0:
        return np.zeros(len(t), bool)
    return (np.abs(t[:, None] - flips[None, :]) <= half_s).any(axis=1)


def test_compare_names_velocity_reversals_when_the_residual_sits_there(tmp_path, ur5, capsys):
    """Mutated null log: a torque bump only near the elbow's velocity reversals."""
    generate_armlog(tmp_path / "logs", ur5, ArmLogSpec(segments=2, duration_s=6.0, seed=4))
    bumped = 0
    for f in sorted((tmp_path / "logs").glob("*.csv")):
        header = f.read_text().splitlines()[0].split(",")
        a = np.loadtxt(f, delimiter=",", skiprows=1)
        qd = a[:, header.index("actual_qd_2")]
        near = _reversal_rows(qd, a[:, 0], 0.05)
        a[near, header.index("target_moment_2")] += 3.0 * np.sign(qd[near] + 1e-12)
        bumped += int(near.sum())
        np.savetxt(f, a, delimiter=",", header=",".join(header), comments="", fmt="%.9f")
    assert bumped > 20
    ds = tmp_path / "ds"
    convert_path(tmp_path / "logs", ds, fmt="tabular", options=ConvertOptions(urdf=ur5))
    res = compare_arm(ds)
    top = res["worst_phases"][0]
    assert top["phase"] == "reversal" and top["joint"] == "elbow_joint"
    assert top["joint_rms_sigma"] > 5 * max(p["joint_rms_sigma"] for p in res["worst_phases"][1:])
    w = res["worst_segments"][0]
    assert w["joint"] == "elbow_joint" and w["phase"] == "reversal"
    assert main(["compare", str(ds)]) == 0
    out = capsys.readouterr().out
    assert "worst phases: reversal" in out and "elbow_joint" in out


def test_cli_diagnose_fit_and_split_by_trajectory(tmp_path, ur5, capsys):
    """One file with time gaps: the segments are the held-out trajectories."""
    generate_armlog(
        tmp_path / "logs",
        ur5,
        ArmLogSpec(effect="joint_friction", segments=3, duration_s=3.0, single_file=True, seed=6),
    )
    ds = tmp_path / "ds"
    assert main(["convert", str(tmp_path / "logs" / "log.csv"), str(ds), "--urdf", str(ur5)]) == 0
    assert [e.segment for e in Dataset.open(ds).episodes] == ["log.csv#0", "log.csv#1", "log.csv#2"]
    capsys.readouterr()
    assert main(["diagnose", str(ds), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["split"] == "by trajectory (3 trajectories), 3 held-out folds"
    assert rep["effects"][0]["name"] == "joint_friction" and rep["effects"][0]["reported"]
    assert main(["diagnose", str(ds), "--effects", "joint_friction,payload"]) == 0
    out = capsys.readouterr()
    assert "missing effect(s): joint_friction" in out.out and "Traceback" not in out.err
    assert main(["fit", str(ds), "--add", "joint_friction", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "fc.elbow_joint" in out and "dry run: nothing written" in out
    assert Dataset.open(ds).physics_history() == []  # nothing written


def _gripper(frozen: bool, v: float) -> str:
    """UR5 with a slide on tool0 and a mimic slide (x2, +0.01 m); frozen: both fixed at ``v``."""

    def slide(name, child, mimic, pos, mass):  # fmt: skip
        if frozen:
            j = f'<joint name="{name}" type="fixed"><origin xyz="{pos} 0 0.05"/>'
        else:
            j = (f'<joint name="{name}" type="prismatic"><origin xyz="0 0 0.05"/><axis xyz="1 0 0"/>'
                 f'<limit lower="0" upper="0.2" effort="50" velocity="0.1"/>{mimic}')  # fmt: skip
        return (f'{j}<parent link="tool0"/><child link="{child}"/></joint><link name="{child}">'
                f'<inertial><mass value="{mass}"/><origin xyz="0 0 0"/>'
                '<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>')  # fmt: skip

    extra = slide("finger_joint1", "finger1", "", v, 1.0) + slide(
        "finger_joint2", "finger2", '<mimic joint="finger_joint1" multiplier="2" offset="0.01"/>',
        2 * v + 0.01, 0.8,
    )  # fmt: skip
    return ur5_urdf().replace("</robot>", extra + "\n</robot>")


def test_franka_layout_with_a_held_gripper_joint(tmp_path):
    """Log of the 6 arm joints only; the URDF also has a slide (and its mimic) the log leaves out."""
    v = 0.06
    frozen, full = tmp_path / "frozen.urdf", tmp_path / "full.urdf"
    frozen.write_text(_gripper(True, v))
    full.write_text(_gripper(False, v))
    truth = generate_armlog(tmp_path / "logs", frozen, ArmLogSpec(segments=2, duration_s=4.0))
    for f in sorted((tmp_path / "logs").glob("*.csv")):  # rename to the Franka-like layout
        lines = f.read_text().splitlines()
        names = {"timestamp": "time"} | {
            f"actual_{a}_{i}": f"{b}{i}" for i in range(6) for a, b in (("q", "q"), ("qd", "dq"))
        } | {f"target_moment_{i}": f"tau_J{i}" for i in range(6)}  # fmt: skip
        lines[0] = ",".join(names.get(c, c) for c in lines[0].split(","))
        f.write_text("\n".join(lines) + "\n")
    with pytest.raises(Exception, match="hold: {finger_joint1: 0.0}"):
        convert_path(
            tmp_path / "logs", tmp_path / "x", fmt="tabular", options=ConvertOptions(urdf=full)
        )
    for held, name in ((v, "ds"), (0.0, "wrong")):
        mapping = tmp_path / f"{name}.yaml"
        mapping.write_text(f"hold: {{finger_joint1: {held}}}\n")
        opts = ConvertOptions(urdf=full, source=TabularOptions(mapping=mapping))
        convert_path(tmp_path / "logs", tmp_path / name, fmt="tabular", options=opts)
    ds = Dataset.open(tmp_path / "ds")
    ep = ds.episodes[0]
    assert ep.stream("joint_states")["derived"] == [
        "position.finger_joint1",
        "velocity.finger_joint1",
    ]
    table = ep.table("joint_states")
    assert np.all(table.column("position.finger_joint1").to_numpy() == v)
    assert "effort.finger_joint1" not in table.schema.names
    assert ds.manifest["provenance"]["mapping"]["segment_00.csv"]["layout"] == "franka"
    good, wrong = compare_arm(tmp_path / "ds"), compare_arm(tmp_path / "wrong")
    sig = np.asarray(truth["effort_noise"])
    rms = np.array([good["joints"][j]["rms_nm"] for j in truth["joints"]])
    np.testing.assert_allclose(rms, sig, rtol=0.2)  # the frozen slide is exactly the generator's
    rms_wrong = np.array([wrong["joints"][j]["rms_nm"] for j in truth["joints"]])
    assert np.max(rms_wrong / sig) > 3  # held at the wrong position: the gravity torque is off


def test_log_without_efforts_converts_and_compare_says_why_it_cannot(tmp_path, ur5, capsys):
    generate_armlog(tmp_path / "logs", ur5, ArmLogSpec(segments=1, duration_s=1.0))
    f = tmp_path / "logs" / "segment_00.csv"
    lines = f.read_text().splitlines()
    keep = [
        i for i, c in enumerate(lines[0].split(",")) if "moment" not in c and "current" not in c
    ]
    f.write_text("\n".join(",".join(ln.split(",")[i] for i in keep) for ln in lines) + "\n")
    assert main(["convert", str(tmp_path / "logs"), str(tmp_path / "ds"), "--urdf", str(ur5)]) == 0
    capsys.readouterr()
    assert main(["compare", str(tmp_path / "ds")]) == 2
    err = capsys.readouterr().err
    assert "neither object_poses nor joint efforts" in err and "Traceback" not in err
