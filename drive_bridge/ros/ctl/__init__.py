"""
``drive_bridge_ctl``: command a running node from a terminal.

cli.py: the parser and main; commands.py and parameters.py: what each command does
through the node; session.py: the node found in the ROS graph, with bounded waits;
values.py: text to ROS values and back, checked before anything is sent.
"""
