"""Planar geometry of the arm in its enclosure: polygons, kinematics, clearance, certificates."""
