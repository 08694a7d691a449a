"""Reconstruction: Gaussian model, rasterizer backends, deformation, methods (later issues)."""
