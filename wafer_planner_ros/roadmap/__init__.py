"""
The probabilistic roadmap of the enclosure (paper section 3), built once and cached.

Where a change belongs: how configurations are sampled, ``samplers``; building it (the
adaptive PRM, certified edges), ``builder``; its graph, ``graph``; its file, ``cache``;
the A* search with the request's ends connected, ``search``; certified shortcuts of a
path, ``shortcut``.
"""
