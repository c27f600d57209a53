"""Benchmarks and robustness sweeps of dpom-warp (run from the repository root)."""
