"""Recording and playback of apc's runs: a rosbag2-compatible MCAP recorder and player, crash
recovery, and runs read back as numpy arrays.
"""
