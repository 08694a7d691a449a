"""Deprecated name of `eventio.representations` (moved in 0.2; this name is removed in 0.3)."""
from simulator._moved import alias

alias(__name__, "eventio.representations")
