"""
Planar geometry of the arm in its enclosure, compiled where it is hot (ROS-free).

Where a change belongs: the arm's forward and inverse kinematics and the wafer's motion,
``kinematics``; distances of the bodies to the walls and their gradients (the hot path),
``clearance``; which body touches which wall and how, ``contacts``; a port's straight
channel, tolerances and margins, ``ports``; polygons read from a cell file, ``polygons``
(validity) on ``predicates`` (exact orientation) and ``planar`` (distances); how far a body
moves per joint, ``lipschitz``; a straight joint-space motion proven free, ``certify``;
``fcl_model`` is the independent reference the tests compare against.
"""
