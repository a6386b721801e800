"""Motion planning: trajectories, time parameterization, (OMPL planning in issue #4)."""
