"""The report of a run: statistics, Markdown tables, figures, the HTML page, provenance.

The modules are imported by their full names (``rippleb.report.tables``); this package
itself loads nothing, so that importing one report module does not load matplotlib.
"""
