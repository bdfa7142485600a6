"""The shared contract of apc: topic names, QoS, message conversion and validation, robot models,
config, rosbag2-compatible MCAP recording and playback.
"""
