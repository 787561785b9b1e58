"""This copy's version: what setuptools-scm recorded when the package was built.

``rippleb/_version.py`` (not in git) is written by setuptools-scm at build time; every
layer reads the version from here, not from the package's ``__init__`` (the top of the
layers, docs/architecture.md).
"""

from __future__ import annotations


def built() -> tuple[str, str | None] | None:
    """``(version, commit id)`` recorded at build time, or None where nothing was built
    (a checkout on ``PYTHONPATH``)."""
    try:
        import rippleb._version as _version
    except ImportError:
        return None
    return str(_version.__version__), getattr(_version, "__commit_id__", None)


def installed_version() -> str:
    """The version setuptools-scm recorded at build time (``rippleb/_version.py``, not in
    git), else the installed distribution's, else ``unknown``."""
    recorded = built()
    if recorded is None:
        from importlib import metadata

        try:
            return metadata.version("rippleb")
        except metadata.PackageNotFoundError:
            return "unknown"
    return recorded[0]


__version__ = installed_version()
