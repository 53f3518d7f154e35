"""``robogs export mjcf DATASET OUT``: the physics scene as MJCF (MuJoCo's XML), a folder::

    OUT/scene.xml        plane, objects, pusher, contact pairs, solver options
    OUT/meshes/*.stl     collision hulls of the objects that have a mesh asset

The document is built by :func:`robogs.format.mjcf.scene_mjcf`, the same builder the
``mujoco`` physics engine compiles, from the dataset's current physics.json revision (its
fitted values: masses, CoM, inertia, friction of every pair, gravity) and the object meshes.
Objects start at their pose at the start of the first episode
(:func:`.urdf_scene.scene_state`). The pusher is a body on four joints (x, y, z, yaw) with a
position servo ``pusher_<j>`` and a velocity servo ``pusher_v<j>`` per joint: replaying the
recorded pusher path means setting, at each step ``k``, the position servos to ``p[k]`` and
the velocity servos to ``(p[k+1] - p[k]) / dt`` (see ``docs/exports.md``).

The robot is not part of this document yet (``robogs export urdf`` writes it); meshes
replaced by their convex hulls and physics.json keys MuJoCo does not represent are listed in
the report notes and in a ``<custom>`` text element of the document.

Dependency note: this module imports only ``robogs.format`` (the builder is format-level), so
the rule that ``robogs.convert`` never imports ``robogs.physics`` holds without an exception.
"""

from __future__ import annotations

from pathlib import Path

from robogs.format import Dataset
from robogs.format.errors import InputError
from robogs.format.mjcf import scene_mjcf

from . import ExportReport, register_exporter
from .urdf_scene import scene_state

__all__ = ["export_mjcf"]


def export_mjcf(ds: Dataset, out: Path) -> ExportReport:
    """Write ``OUT/scene.xml`` and ``OUT/meshes/`` from the dataset's physics.json.

    Raises:
        InputError: the dataset has no physics.json or no rigid object in it.
        FormatError: a physics.json value the scene needs is missing or malformed.
    """
    if not ds.manifest.get("physics"):
        raise InputError(
            "dataset has no physics.json",
            path=ds.manifest_path,
            hint="run `robogs physics init` first",
        )
    physics = ds.physics()
    objects = physics.get("objects") or {}
    rigid = [n for n, e in objects.items() if isinstance(e, dict) and e.get("equation") == "rigid"]
    if not rigid:
        raise InputError(
            "physics.json has no rigid object to simulate",
            path=ds.resolve("physics.json"),
            where="objects",
        )
    meshes = {}
    for name, entry in objects.items():
        if name in ("table", "pusher") or not isinstance(entry, dict):
            continue
        if "mesh" in (ds.assets.get(name) or {}):
            meshes[name] = ds.mesh(name)
    state = scene_state(ds, [n for n in objects if n not in ("table", "pusher")])
    poses = {n: p.pose for n, p in state.objects.items()}
    scene = scene_mjcf(
        physics, meshes=meshes, poses=poses, model_name=f"{ds.name}_scene", meshdir="meshes/"
    )
    xml = scene.xml
    remarks = [*scene.notes, *(f"not represented: {k}" for k in scene.unmapped)]
    remarks.append(f"physics revision {physics.get('revision')} of dataset {ds.name!r}")
    text = "; ".join(remarks).replace('"', "'").replace("&", "and").replace("<", "(")
    xml = xml.replace(
        "</mujoco>", f'  <custom>\n    <text name="robogs" data="{text}" />\n  </custom>\n</mujoco>'
    )
    (out / "scene.xml").write_text(xml, encoding="utf-8")
    files = ["scene.xml"]
    if scene.assets:
        (out / "meshes").mkdir()
        for fname, data in sorted(scene.assets.items()):
            (out / "meshes" / fname).write_bytes(data)
            files.append(f"meshes/{fname}")
    notes = [*scene.notes, "robot not included (use `robogs export urdf` for it)"]
    if scene.unmapped:
        notes.append(f"not represented in MuJoCo: {', '.join(scene.unmapped)}")
    return ExportReport(
        out=out,
        files=files,
        notes=notes,
        facts={
            "objects": scene.objects,
            "pusher": scene.pusher,
            "pairs": [list(p) for p in scene.pairs],
            "hulled_meshes": sorted(meshes),
            "unmapped": scene.unmapped,
            "physics_revision": physics.get("revision"),
        },
    )


register_exporter(
    "mjcf",
    export_mjcf,
    output="folder",
    help="MuJoCo MJCF scene: plane, objects, servo-driven pusher, fitted contact parameters",
)
