"""Fuzzing MCAP files, ROS 1 bags and ROS 2 bag folders through ``robogs convert``."""

from .fuzzing import fuzz_test

test_fuzz_mcap = fuzz_test("mcap")
test_fuzz_mcap_messages = fuzz_test("mcap_messages")
test_fuzz_ros1 = fuzz_test("ros1")
test_fuzz_ros2 = fuzz_test("ros2")
