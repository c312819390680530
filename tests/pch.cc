// The object kinemo_test_pch and kinemo_test_pch_base compile: empty, it
// exists for their headers (tests/pch.h, tests/pch_base.h).
