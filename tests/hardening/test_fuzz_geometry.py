"""Fuzzing splat PLY, URDF XML and meshes (OBJ, PLY, STL, COLLADA, GLB)."""

from .fuzzing import fuzz_test

test_fuzz_splats = fuzz_test("splats")
test_fuzz_urdf = fuzz_test("urdf")
test_fuzz_robot_urdf = fuzz_test("robot_urdf")
test_fuzz_meshes = fuzz_test("meshes")
