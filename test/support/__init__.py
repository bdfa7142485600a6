"""The tests' shared harness, one job a module.

- :mod:`.graph`: a ROS graph per test (the ``graph`` fixture); :mod:`.qos`: the test's own
  readers and writers, deep enough never to drop; :mod:`.nodes`: apc's nodes run in the test
  process (parameter overrides in, diagnostics counters out, also from a recording);
  :mod:`.arm`: the arm and period the node tests run.
- :mod:`.capture`: the nodes' own output by topic and stamp, and its checks (finite, equal to
  the offline loop); :mod:`.stand_ins`: a plant or controllers played by the test;
  :mod:`.parameter_rig`: the feedback node driven through its parameter service;
  :mod:`.fuzz`: hypothesis strategies of invalid and extreme messages.
- :mod:`.processes`: node processes and their parameter files, always stopped;
  :mod:`.observer`: what node processes publish, seen from the test process (the
  ``observer`` fixture); :mod:`.netns`: two network namespaces over a lossy link;
  :mod:`.report`: measurements printed for docs/reliability.md.
- :mod:`.plans`: a scripted stand-in for robot mode's plan.
"""
