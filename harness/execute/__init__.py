"""Stage 5, execution: jobs with stable keys, the crash-safe store, executors, the runner."""
