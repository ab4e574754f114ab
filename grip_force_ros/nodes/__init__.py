"""The ROS 2 shells: one rclpy node per executable (controller, sim_instrument, master).

Around them: QoS and message checks (``common``), parameter descriptors from the schema
(``ros_params``), a node's own process: the peers it leaves after, its stack signal, its
teardown watcher (``lifetime``, no rclpy); nodes started as child processes
(``processes``, no rclpy) or inside this process (``harness``).
"""
