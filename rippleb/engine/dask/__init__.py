"""Rows on a ``dask.distributed`` cluster: the client side (:mod:`~rippleb.engine.dask.executor`),
the address check (:mod:`~rippleb.engine.dask.connect`) and what a worker does with a row
(:mod:`~rippleb.engine.dask.worker`), which runs it in the same process boundary as a local
run (:mod:`rippleb.engine.process`). The modules are imported by their full names; this
package itself loads nothing (and so ``import dask`` inside it is the third-party package).
"""
