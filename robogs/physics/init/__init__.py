"""Physics from the data: ``robogs physics init | show | set``.

:func:`init_physics` writes a physics.json revision built from what a dataset holds (objects,
their geometry, the support plane, the pusher from the URDF's collision geometry, priors from
materials), with the source of every value (:mod:`.provenance`); :func:`set_physics_values`
edits values by dotted key, one revision per call. See :mod:`.build` for the order of the
sources and :mod:`.priors` for the material table and the provider interface.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from robogs.format.errors import InputError
from robogs.physics.init.build import InitResult, ObjectSpec, build_physics, parse_object_specs
from robogs.physics.init.priors import MATERIALS, MaterialPrior, MaterialTable, PriorProvider
from robogs.physics.init.provenance import Entry, format_table, parse_assignment, record, set_value

__all__ = [
    "init_physics",
    "set_physics_values",
    "show_physics",
    "InitResult",
    "ObjectSpec",
    "parse_object_specs",
    "PriorProvider",
    "MaterialTable",
    "MaterialPrior",
    "MATERIALS",
    "Entry",
    "format_table",
]

_CARRY = ("joints", "sensors", "payload")  # kept from the previous revision on --force


def _open(dataset: Any):
    from robogs.format.dataset import Dataset

    return dataset if isinstance(dataset, Dataset) else Dataset.open(Path(dataset))


def init_physics(
    dataset: Any,
    *,
    objects: dict[str, ObjectSpec] | list[str] | None = None,
    pusher_link: str | None = None,
    provider: PriorProvider | None = None,
    force: bool = False,
    write: bool = True,
) -> InitResult:
    """Build physics.json from the dataset and (``write``) store it as a new revision.

    Args:
        dataset: a ``Dataset`` or its folder.
        objects: ``--object`` items (``["box=material:wood"]``) or parsed :class:`ObjectSpec`.
        pusher_link: force the pusher link instead of the closest one.
        provider: material priors (default :class:`MaterialTable`).
        force: replace an existing physics.json (its ``joints``, ``sensors`` and ``payload``
            are kept; the old revision stays in ``physics/history``).

    Returns:
        the document written (``physics`` has its ``revision``) and the source of every value.
    """
    ds = _open(dataset)
    if isinstance(objects, list):
        objects = parse_object_specs(objects)
    if ds.manifest.get("physics") is not None and not force and write:
        raise InputError(
            "the dataset already has a physics.json",
            path=ds.root,
            hint="pass --force to replace it with a new revision (history is kept), "
            "or edit values with robogs physics set",
        )
    res = build_physics(ds, specs=objects, pusher_link=pusher_link, provider=provider)
    doc = dict(res.physics)
    if ds.manifest.get("physics") is not None:
        old = ds.physics()
        for k in _CARRY:
            if k in old:
                doc[k] = old[k]
    doc = record(doc, res.entries)
    if write:
        with ds.edit() as w:
            doc["revision"] = w.set_physics(doc, note="robogs physics init")
            w.commit()
    res.physics = doc
    return res


def show_physics(dataset: Any) -> str:
    """The current physics.json as a table of key, value and source."""
    return format_table(_open(dataset).physics())


def set_physics_values(dataset: Any, assignments: list[str]) -> dict[str, Any]:
    """Set ``KEY=VALUE`` items (dotted keys, JSON values) as one new revision; returns it.

    Each key's source becomes ``user``. The document is schema-checked before it is written.
    """
    ds = _open(dataset)
    if not assignments:
        raise InputError(
            "nothing to set", hint="e.g. robogs physics set DS objects.box.mass_kg=0.3"
        )
    doc = ds.physics()
    entries = []
    for item in assignments:
        key, value = parse_assignment(item)
        if key in ("revision", "parent_revision", "note") or key.startswith("sources"):
            raise InputError(f"{key} is kept by robogs and cannot be set", where=item)
        doc = set_value(doc, key, value)
        # a list item's source is recorded on the list (the value the table shows)
        parts = key.split(".")
        node: Any = doc
        for i, p in enumerate(parts):
            if isinstance(node, list):
                key = ".".join(parts[:i])
                break
            node = node[p]
        entries.append(Entry(key, _get(doc, key), "user", None, "robogs physics set"))
    doc = record(doc, entries)
    for k in ("revision", "parent_revision", "note"):
        doc.pop(k, None)
    with ds.edit() as w:
        doc["revision"] = w.set_physics(doc, note="robogs physics set " + " ".join(assignments))
        w.commit()
    return doc


def _get(doc: dict[str, Any], key: str) -> Any:
    node: Any = doc
    for p in key.split("."):
        node = node[p]
    return node
