"""
The work cell, validated once: enclosure, robot, its limit sets, stations (ROS-free).

Where a change belongs: a new key of the cell file or a new check of one, in the module
that reads that section (``robot``: the arm, its bodies and limits; ``stations``: named
places, their elbow branches and ports; ``model``: the enclosure and the whole ``Cell``),
each failure naming its key path through ``schema``; how the YAML text itself is read
safely, ``document``; the loaded and empty limit values, ``limits`` (what a limit means to
the optimisers and the verification is ``trajectory.constraints``).
"""
