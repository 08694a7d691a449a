"""The toolkit's ground floor: strict configs, atomic file output and locks, image I/O, checkpoints,
colour conversions, image metrics and run provenance. It imports no other package of the project."""

__version__ = "0.1.0"
