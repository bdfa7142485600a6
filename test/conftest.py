"""Shared test set-up: every test process talks DDS on its own random domain, on localhost only."""

from __future__ import annotations

import os
import random

import pytest
from support.graph import Graph
from support.observer import Observer

# Set before any rclpy context is created (contexts read the environment at init), so tests that
# run nodes never see another run's traffic and never leave this machine.
os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 200)))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"


@pytest.fixture
def ros_domain() -> str:
    """The DDS domain of this test process (children inherit it)."""
    return os.environ["ROS_DOMAIN_ID"]


@pytest.fixture
def graph():
    """A :class:`rosgraph.Graph` for the test's nodes; torn down after the test."""
    g = Graph()
    try:
        yield g
    finally:
        g.close()


@pytest.fixture
def observer():
    """An :class:`observer.Observer` of the test's node processes; closed after the test."""
    obs = Observer()
    try:
        yield obs
    finally:
        obs.close()
