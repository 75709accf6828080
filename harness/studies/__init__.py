"""Studies built on the runner: engine agreement, convergence, benchmarks."""
