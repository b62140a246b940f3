"""
Layout studies: many variants of one cell, each planned and measured (``wafer-study``).

``parameters``: what can vary and how a value is applied to a cell document; ``spec``: the
study file; ``evaluate``: one variant from its cell to its row of results; ``results``: the
study's directory (rows appended as variants finish, resumable, one writer at a time);
``executors``: the local cores or a Ray cluster; ``search``: an Optuna search over the
same parameters; ``report``: the best variants and the figures.
"""
