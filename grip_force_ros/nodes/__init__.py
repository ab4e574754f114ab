"""The rclpy nodes: controller, sim_instrument, master (the only ROS code)."""
