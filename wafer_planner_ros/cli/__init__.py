"""
The command-line tools (console scripts), one module each; none needs ROS but ``client``.

``plan`` (``wafer-plan``), ``roadmap``, ``replay``, ``review`` (with ``review_index``),
``recover``, ``client`` (``wafer-plan-client``, through ``node.client``), ``kernels``
(``wafer-kernels``), ``study`` (``wafer-study``). What they share goes in ``common``
(options, progress, recordings, JSON) and ``summary`` (how a plan's figures are worded).
A tool answers through ``service.planning`` like the node: a change to how a request is
answered belongs there, not in a tool.
"""
