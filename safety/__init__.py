"""The safety layer between a policy's command and the robot."""
