"""Planning, scheduling, executing and isolating the rows of a run.

The modules are imported by their full names (``rippleb.engine.runner``); this package
itself loads nothing, so that importing one engine module does not load the others.
"""
