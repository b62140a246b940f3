"""
The ROS 2 edge: a thin node around the ROS-free core (the only subpackage importing rclpy).

Where a change belongs: a topic, service or parameter of the node, ``planner_node`` (its
health on ``/diagnostics``: ``health``; recording switched on and off: ``recording_switch``);
the queues, deadlines and watchdog, ``worker``; loading the cell, roadmap, kernels and
station table, ``loader``, then ``serving`` (a loaded roadmap taking over); what is
published, ``messages`` and ``markers``; what is recorded, ``recording``; the Foxglove live
view, ``live`` (the node's side) over ``live_server`` (the WebSocket protocol), and the
robot it shows, ``live_robot``; the QoS everything here uses, ``qos``; the process and its
start-up, ``main``, ``process`` and ``startup``; failing safely, ``faults``; stop requests,
``stops`` (their subscription and its waiting, ``stop_requests``); talking to a running
node, ``client`` and ``replay_publish``; the simulated arm ``wafer-sim``, ``sim``. How a
request is planned is not decided here but in ``service.planning``.
"""
