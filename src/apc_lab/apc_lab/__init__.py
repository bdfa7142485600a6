"""apc's lab: the launch-free experiment runner, scenarios, the paper's experiment, the robot
comparison, analysis, plots and the parameter-file writer. Nothing depends on it.
"""
