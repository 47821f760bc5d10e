"""sampler: GMM scenario model, constraints, constrained sampling, scenario builder."""
