"""Shared base of the toolkit: strict configs, atomic file output and the `e4dgs` command line."""

__version__ = "0.1.0"
