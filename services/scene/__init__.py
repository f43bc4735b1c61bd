"""Scene estimation."""
