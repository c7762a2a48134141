"""Results of a solve and their checks: outputs, grip wrenches, residual, stability."""
