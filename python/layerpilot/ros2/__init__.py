"""ROS 2 without ROS: layerpilot's topics as rmw_zenoh publishes them, ROS 2 types and CDR (rosbags)."""
