"""Stage 1, inputs: cane descriptions (YAML), the rig CSV format, datasets that pair them."""
