"""Dataset generator: the bpy render loop that feeds the event simulator (arrives with the dataset issue)."""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
