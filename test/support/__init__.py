"""The system tests' shared harness: a ROS graph per test (:mod:`.graph`, the ``graph``
fixture), node processes and their parameter files (:mod:`.processes`), and a scripted stand-in
for robot mode's plan (:mod:`.plans`)."""
