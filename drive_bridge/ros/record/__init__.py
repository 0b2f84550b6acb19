"""
``drive_bridge_record``: record the bridge's topics into a rosbag2 bag.

cli.py: the parser and main (no rosbags needed to start); recorder.py: the bag.
"""
