// The object kinemo_test_pch compiles: empty, it exists for tests/pch.h.
