"""The `e4dgs` command line (the top of the toolkit; every library package is below it)."""
from common import __version__  # noqa: F401
