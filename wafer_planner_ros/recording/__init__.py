"""Recording queries to MCAP in the rosbag2 layout, and reading them back."""
