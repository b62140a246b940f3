"""
Moves through a port: the straight way in and out, built exactly, and the whole move.

Inside a port the motion is one-dimensional: the wafer centre moves along the port's axis
with the blade on its heading, so the joints follow the inverse kinematics of that straight
line on the elbow branch, exactly (``channel``). Only its timing is free: a jerk-limited
profile along the axis (``timing``). A move from inside one port to inside another is that
way out, a free transfer between the two port mouths, and that way in, joined at the mouth
states (position, velocity, acceleration) into one curve (``through``); stopping at the
mouths is the case of zero mouth speed. How a move through a port is chosen among elbow
branches and blended is ``planner.through``'s.
"""
