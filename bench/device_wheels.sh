#!/usr/bin/env bash
# Fill .whl/ for bench/device_run.sh (issue 23): the packages robogs's render, reconstruct and
# training tests import that the lent GPU image lacks (its list: ../.library/device/KINDS.md),
# at the versions installed in .venv, for CPython 3.12 on x86_64, plus a robogs wheel for its
# entry points. rtree is trimesh's spatial index (closest-point binding); a pip install gets it
# through yourdfpy's trimesh[easy], which --no-deps skips. Run here, in the repository root;
# .whl/ must be git-ignored (echo /.whl/ >> .git/info/exclude) and is carried by the run.
set -euo pipefail
cd "$(dirname "$0")/.."
PIP=${PIP:-.venv/bin/pip}
pkgs=(trimesh yourdfpy rtree jsonschema jsonschema-specifications referencing rpds-py defusedxml
  plyfile pycollada mcap)
pins=()
for p in "${pkgs[@]}"; do
  v=$("$PIP" show "$p" 2>/dev/null | awk '/^Version:/{print $2}')
  [[ -n $v ]] || { echo "device_wheels: $p is not installed in .venv; install the project first" >&2; exit 1; }
  pins+=("$p==$v")
done
mkdir -p .whl
rm -f .whl/robogs-*.whl
"$PIP" download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 \
  --platform manylinux_2_24_x86_64 --platform manylinux_2_17_x86_64 \
  --platform manylinux2014_x86_64 --platform manylinux1_x86_64 -d .whl "${pins[@]}"
"$PIP" wheel -q --no-deps . -w .whl
du -sh .whl
