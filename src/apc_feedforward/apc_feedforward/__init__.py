"""Trajectory planning (4-3-4, quintic, waypoints) and nominal torques by recursive Newton-Euler
for apc.
"""
