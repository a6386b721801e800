"""Motion planning: OMPL planners, time parameterization (toppra), dense trajectory checks."""
