"""Command-line tools (console scripts); they need no ROS."""
