"""The process boundary: where rippleb's code ends and a method's begins.

Every method's code (its import, fit and steps) runs in a worker forked by a keeper
(:mod:`~rippleb.engine.process.keeper`), from a fork server that holds no truth
(:mod:`~rippleb.engine.process.forkserver`), confined by the kernel's walls
(:mod:`~rippleb.engine.process.isolation`, :mod:`~rippleb.engine.process.sandbox`), with its
output bounded (:mod:`~rippleb.engine.process.joblog`); :mod:`~rippleb.engine.process.pool`
runs such jobs side by side. The modules are imported by their full names; this package
itself loads nothing.
"""
