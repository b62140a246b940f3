"""The probabilistic roadmap: samplers, builder, graph, cache, search and shortcuts."""
