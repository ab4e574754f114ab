"""The ROS 2 shells: one rclpy node per executable (controller, sim_instrument, master).

Around them: QoS and message checks (``common``), parameter descriptors from the schema
(``ros_params``), a node's own process: the peers it leaves after, its stack signal, its
teardown watcher (``lifetime``, no rclpy). Starting nodes as child processes or inside
a test's process is the laboratory's (:mod:`grip_force_ros.lab.processes`,
:mod:`grip_force_ros.lab.harness`).
"""
