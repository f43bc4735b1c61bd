"""The robot model shared by the sim, the controller and the viewer: names, limits, URDF."""
