"""Image processing shared by services (numpy and OpenCV only; no bus, no rerun)."""
