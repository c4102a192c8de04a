// Compiles tests/support/test_pch.hpp once for every test binary (REUSE_FROM).
