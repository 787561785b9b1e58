"""Scoring a row: the accuracy, response and truth-free columns, and the rules that keep an
estimate that cannot be scored right from being ``ok``.

One place scores every row (:func:`rippleb.scoring.row.score_row`), whoever ran it: the
scheduler of a run, :func:`rippleb.engine.runner.evaluate` and the tuner. The modules are
imported by their full names (``rippleb.scoring.metrics``); this package itself loads nothing.
"""
