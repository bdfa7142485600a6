"""apc's simulated arms: the plant (Lagrange-Euler, RK4) behind plant_node and a ros2_control-style
robot (apc's plant or MuJoCo) behind robot_sim. It imports no controller."""
