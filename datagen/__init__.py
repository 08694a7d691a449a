"""Dataset generator: the bpy render loop that feeds the event simulator."""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
