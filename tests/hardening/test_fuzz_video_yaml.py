"""Fuzzing video containers, frame-stamp CSVs, calibration YAML/INI and the YAML maps."""

from .fuzzing import fuzz_test

test_fuzz_video = fuzz_test("video")
test_fuzz_stamps = fuzz_test("stamps")
test_fuzz_calibration = fuzz_test("calibration")
test_fuzz_tabular_map = fuzz_test("tabular_map")
test_fuzz_role_map = fuzz_test("role_map")
