"""The package version, in a module of its own so that any module can import it without
importing the package ``__init__`` (no import cycles)."""

__version__ = "0.4.0"
