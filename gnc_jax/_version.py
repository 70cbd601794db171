"""The package version (a leaf: the store records it with every study)."""

__version__ = "0.1.0"
