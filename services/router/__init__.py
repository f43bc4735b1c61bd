"""The run's Zenoh router: a Python session in router mode (no zenohd binary exists here)."""
