"""Stage 4, measurement: line fits and field stiffness extraction."""
