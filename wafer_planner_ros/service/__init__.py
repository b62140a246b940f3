"""
The planner as a service, ROS-free: the one policy by which every request is answered.

Where a change belongs: how a request is answered (the station table first, a time budget,
the curve method), ``planning``, used alike by the node, ``wafer-plan`` and
``wafer-replay``; reading a request, ``requests``; the node's parameters, ``settings``; the
station table, ``table`` (its build order ``table_build``, its file ``table_store``, an
entry and its validation ``table_entry``); the optima kept beside it, ``optima_store``; a
curve of one limit set answering another,
``adoption``; the swap cycle through the ports, ``cycle``; messages as bytes, ``cdr`` and
``marker_cdr``; every kernel compiled before the first request, ``warmup``; the node's
requests planned in a child process, ``planning_process``; the stops made ahead of a
running move, ``prepared_stops``, and the child process finding them, ``stop_maker``; a
child process of the package and its pipes, ``child_process``; a trajectory executed as
``joint_trajectory_controller`` does (the simulated arm's), ``execution``.
"""
