"""Recursive least-squares identification of the perturbation model and one-step optimal feedback
for apc, plus computed-torque and PD baselines.
"""
