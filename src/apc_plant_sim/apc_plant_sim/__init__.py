"""Simulated arm (Lagrange-Euler, RK4), launch-free experiment runner, analysis and plots
for apc.
"""
