"""Fuzzing the manifest and the JSON sidecars (cameras, physics, MDH) through ``robogs validate``."""

from .fuzzing import fuzz_test

test_fuzz_manifest = fuzz_test("manifest")
test_fuzz_manifest_full = fuzz_test("manifest_full")
test_fuzz_sidecar = fuzz_test("sidecar")
