"""Update stages: how a committed shape moves to new targets (Newton, IPOPT, warm starts)."""
