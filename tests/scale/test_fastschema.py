"""The quick "surely valid" schema test never passes a document that ``jsonschema`` rejects.

Oracle: ``jsonschema`` (Draft 2020-12) itself, on valid manifests and sidecars and on thousands
of random one-place mutations of them (a value replaced by another type, an edge number, a
removed or an added key). A fast pass must mean zero ``jsonschema`` errors; a valid document
must pass fast (or the speed-up is lost).
"""

from __future__ import annotations

import copy
import json
import math
import random
from typing import Any

import pytest
from jsonschema import Draft202012Validator

from robogs.format.dataset import Dataset
from robogs.format.fastschema import compile_schema, surely_valid
from robogs.format.schemas import load_schema, schema_problems
from robogs.synth.bulk import write_bulk_dataset

#: values a mutation may put in place of another
_ODD = [None, True, False, 0, -1, 1.0, 2.5, -0.0, math.nan, math.inf, 2**63, -(2**63) - 1, "",
        "x" * 1100, "ep 1", "../x", [], [1], {}, {"a": 1}, "a" * 64, "0" * 64]  # fmt: skip


def _places(doc: Any, path: tuple = ()) -> list[tuple]:
    out = [path]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _places(v, (*path, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:3]):
            out += _places(v, (*path, i))
    return out


def _mutate(doc: Any, rng: random.Random) -> Any:
    doc = copy.deepcopy(doc)
    path = rng.choice(_places(doc)[1:])
    parent = doc
    for p in path[:-1]:
        parent = parent[p]
    key, what = path[-1], rng.random()
    if what < 0.2 and isinstance(parent, dict):
        del parent[key]
    elif what < 0.3 and isinstance(parent, dict):
        parent[rng.choice(["extra", "kind", "sha256", "rows", "id"])] = rng.choice(_ODD)
    else:
        parent[key] = rng.choice(_ODD)
    return doc


@pytest.fixture(scope="module")
def documents(tmp_path_factory) -> list[tuple[str, Any]]:
    """(schema name, valid document): bulk manifests (flat, merged sharded) and sidecars."""
    base = tmp_path_factory.mktemp("fast")
    write_bulk_dataset(base / "flat", n_episodes=3, duration_s=0.05)
    write_bulk_dataset(base / "sharded", n_episodes=4, duration_s=0.05, chunk_size=2)
    docs = [
        ("manifest", json.loads((base / "flat" / "manifest.json").read_text())),
        ("manifest", Dataset.open(base / "sharded").full_manifest()),
    ]
    from robogs.synth.scene import synthesize  # a scene with cameras, physics, assets

    scene = base / "scene"
    synthesize(scene, seed=0, size="small", progress=False)
    docs.append(("manifest", json.loads((scene / "manifest.json").read_text())))
    docs.append(("physics", json.loads((scene / "physics.json").read_text())))
    docs += [("camera", json.loads(p.read_text())) for p in sorted(scene.glob("cameras/*.json"))]
    return docs


def test_valid_documents_pass_fast(documents):
    assert {n for n, _ in documents} == {"manifest", "physics", "camera"}
    for name, doc in documents:
        assert list(Draft202012Validator(load_schema(name)).iter_errors(doc)) == []
        assert surely_valid(load_schema(name), doc), name


def test_a_fast_pass_is_never_a_jsonschema_error(documents):
    rng = random.Random(7)
    passed = rejected = 0
    for name, doc in documents:
        schema = load_schema(name)
        strict = Draft202012Validator(schema)
        for _ in range(1500 if name == "manifest" else 300):
            bad = _mutate(doc, rng)
            errors = list(strict.iter_errors(bad))
            if surely_valid(schema, bad):
                assert errors == [], (name, bad, errors[0].message)
                passed += 1
            else:
                rejected += 1
                assert len(schema_problems(name, bad)) == len(errors)  # jsonschema ran
    assert passed > 100 and rejected > 1000, (passed, rejected)


@pytest.mark.parametrize(
    ("schema", "doc", "ok"),
    [
        ({"type": "integer", "minimum": 0}, 3, True),
        ({"type": "integer", "minimum": 0}, -1, False),
        ({"type": "integer"}, True, False),  # bool is not an integer
        ({"type": "integer"}, 1.0, False),  # valid for jsonschema: "not sure" here
        ({"minimum": 0}, "text", True),  # bounds apply to numbers only
        ({"minimum": 0}, math.nan, False),  # not sure
        ({"enum": [1, "a"]}, True, False),  # True is not 1
        ({"enum": [1, "a"]}, 1.0, True),
        ({"const": [1]}, [1], False),  # containers: not sure
        ({"pattern": "^a"}, "ab", True),
        ({"pattern": "b"}, "ab", True),  # re.search, as jsonschema
        ({"properties": {"a": {"type": "string"}}, "additionalProperties": False}, {"b": 1}, False),
        ({"patternProperties": {"^x": {}}, "additionalProperties": False}, {"x": 1}, False),
        ({"unevaluatedProperties": False}, {}, False),  # unknown keyword: not sure
        ({"$ref": "#/$defs/n", "$defs": {"n": {"type": "number"}}}, 2, True),
        ({"$ref": "#/$defs/n", "$defs": {"n": {"items": {"$ref": "#/$defs/n"}}}}, [[1]], True),
        ({"$ref": "#/$defs/n", "$defs": {"n": {"items": {"$ref": "#/$defs/n"}}}}, [[1], 2], True),
        (
            {
                "$ref": "#/$defs/n",
                "$defs": {"n": {"type": "array", "items": {"$ref": "#/$defs/n"}}},
            },
            [[1]],
            False,
        ),
    ],
)
def test_keywords(schema, doc, ok):
    assert compile_schema(schema)(doc) is ok
    if ok:
        assert list(Draft202012Validator(schema).iter_errors(doc)) == []
