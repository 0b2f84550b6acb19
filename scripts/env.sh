# Sourced by the scripts: the environment every demo, test and CI run needs.
# ROS discovery stays on this machine (the default multicasts on the network).
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# Jazzy does not check message field types unless asked (an int in a Float32 goes out as 0.0).
export ROS_PYTHON_CHECK_FIELDS=1
export AMENT_PREFIX_PATH="${VENV:?}"
export PYTHONUNBUFFERED=1
