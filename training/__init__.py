"""Training-only pieces beside the trainer: the optimiser and its schedule, densification, parameter surgery."""
