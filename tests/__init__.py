"""The test suite (a package, so that tests/service does not shadow the top-level service package)."""
