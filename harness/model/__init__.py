"""Stage 2, the model: one configuration, geometry, diameter line, stiffness formulas, the chain IR."""
