"""Fuzzing parquet tables (dataset tables through ``validate``, joint logs through ``convert``)."""

from .fuzzing import fuzz_test

test_fuzz_tables = fuzz_test("tables")
test_fuzz_tabular_csv = fuzz_test("tabular_csv")
test_fuzz_tabular_parquet = fuzz_test("tabular_parquet")
