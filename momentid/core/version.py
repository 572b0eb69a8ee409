"""The package's version, in the lowest layer so that every layer may name it (``report.html``'s
provenance, ``momentid --version``); ``momentid.__version__`` is this one."""

__all__ = ["__version__"]

#: The version of momentid (pyproject.toml's ``version``).
__version__ = "0.1.0"
