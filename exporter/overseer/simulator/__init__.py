"""The paper's virtual robots: a fleet publishing real diagnostics traffic for demos, tests and benchmarks."""
