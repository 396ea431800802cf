"""The geometry (MCmatlab's ``model.G``: the voxel cuboid, :mod:`~mcmatlab_py.geometry.cuboid`)
and its media (:mod:`~mcmatlab_py.geometry.media`, the spectral library
:mod:`~mcmatlab_py.geometry.spectra`, the media evaluated on the voxels
:mod:`~mcmatlab_py.geometry.media_bins`, voxels inside STL meshes
:mod:`~mcmatlab_py.geometry.stl`)."""

from .cuboid import Geometry
from .media import Medium
from .spectra import calc_mua, calc_mus
from .stl import find_inside_voxels

__all__ = ["Geometry", "Medium", "calc_mua", "calc_mus", "find_inside_voxels"]
