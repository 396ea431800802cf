"""Finite-element heat diffusion on tetrahedral scikit-fem meshes.

This package knows nothing of photons or filters: it takes a voxel-wise
power density (W/cm^3), volumetric heat capacities (J cm^-3 K^-1) and thermal
conductivities (W cm^-1 K^-1) and returns temperatures (deg C).
"""
