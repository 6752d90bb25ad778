"""The dVRK over ROS 2 (CRTK topics). Needs the ``ros`` extra; nothing outside this package imports rclpy."""
