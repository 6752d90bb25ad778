"""PyBullet simulation of soft-tissue retraction with the dVRK PSM."""
