"""A vectorised ray caster for the sim's analytic shapes (ellipsoids, cylinders, boxes, leaves)."""
