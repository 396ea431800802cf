"""Geometry: ``geom_func`` with parameters (MCmatlab's geomFuncParams) and from STL meshes."""

import math

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")

from mcmatlab_py import Medium, Model, find_inside_voxels  # noqa: E402


def grid(n: int, L: float = 1.0):
    """Voxel centres of an n^3 cuboid [-L/2, L/2]^2 x [0, L], as G passes them."""
    model = Model()
    model.G.nx = model.G.ny = model.G.nz = n
    model.G.Lx = model.G.Ly = model.G.Lz = L
    return np.meshgrid(model.G.x, model.G.y, model.G.z, indexing="ij")


def test_box_from_stl_file_is_exact(tmp_path):
    # faces half-way between voxel centres: no centre is ambiguous, the count is exact
    X, Y, Z = grid(20)
    path = tmp_path / "box.stl"
    pv.Box(bounds=(-0.2, 0.3, -0.25, 0.15, 0.1, 0.6)).save(path)
    inside = find_inside_voxels(X, Y, Z, str(path))
    expected = (X > -0.2) & (X < 0.3) & (Y > -0.25) & (Y < 0.15) & (Z > 0.1) & (Z < 0.6)
    assert inside.dtype == bool and np.array_equal(inside, expected)
    assert inside.sum() * 0.05**3 == pytest.approx(0.5 * 0.4 * 0.5)


def test_sphere_volume_converges_to_the_analytic_volume(tmp_path):
    r, centre = 0.3, (0.013, -0.021, 0.507)
    path = tmp_path / "sphere.stl"
    sphere = pv.Sphere(radius=r, center=centre, theta_resolution=200, phi_resolution=200)
    sphere.save(path)
    exact = 4 / 3 * math.pi * r**3
    assert sphere.volume == pytest.approx(exact, rel=1e-3)  # faceting of the written mesh
    hs, errors = [], []
    for n in (16, 32, 64):
        X, Y, Z = grid(n)
        h = 1.0 / n
        volume = find_inside_voxels(X, Y, Z, path).sum() * h**3
        # a voxel is misclassified only if the surface passes within half its diagonal
        # of its centre: the error is bounded by the area times that half diagonal
        shell = 4 * math.pi * r**2 * (math.sqrt(3) / 2 * h)
        assert abs(volume - sphere.volume) <= shell
        hs.append(h)
        errors.append(abs(volume - sphere.volume) / sphere.volume)
    order = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert order > 1.0  # at least the first order of the shell bound (about 2 observed)
    assert errors[-1] < 2e-3


def test_transform_scales_mirrors_and_translates_like_mcmatlab():
    # MCmatlab example 18: points become A p + v (mm to cm, mirror z, then translate)
    X, Y, Z = grid(20)
    box_mm = pv.Box(bounds=(-2.0, 3.0, -2.5, 1.5, -1.0, 4.0))
    A = 0.1 * np.diag([1.0, 1.0, -1.0])
    inside = find_inside_voxels(X, Y, Z, box_mm, A=A, v=(0.0, 0.0, 0.5))
    expected = (X > -0.2) & (X < 0.3) & (Y > -0.25) & (Y < 0.15) & (Z > 0.1) & (Z < 0.6)
    assert np.array_equal(inside, expected)


def test_bad_meshes_and_grids_raise_value_errors(tmp_path):
    X, Y, Z = grid(8)
    with pytest.raises(ValueError, match="is not closed"):
        find_inside_voxels(X, Y, Z, pv.Plane())
    with pytest.raises(ValueError, match="does not exist"):
        find_inside_voxels(X, Y, Z, tmp_path / "missing.stl")
    with pytest.raises(ValueError, match="A must be a finite 3 x 3 matrix"):
        find_inside_voxels(X, Y, Z, pv.Sphere(), A=np.eye(2))
    with pytest.raises(ValueError, match="X must be a meshgrid"):
        find_inside_voxels(np.random.default_rng(0).random(X.shape), Y, Z, pv.Sphere())


def stl_model(path, geom_func):
    model = Model()
    model.G.nx, model.G.ny, model.G.nz = 16, 16, 16
    model.G.Lx = model.G.Ly = model.G.Lz = 1.0
    model.G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0), Medium("tissue", 1.0, 100.0, 0.9)]
    model.G.geom_func = geom_func
    model.G.geom_func_params = {"file": path, "v": (0.0, 0.0, 0.5)}
    return model


def test_geom_func_params_reach_a_four_argument_geom_func(tmp_path):
    path = tmp_path / "sphere.stl"
    pv.Sphere(radius=3.0, theta_resolution=60, phi_resolution=60).save(path)  # mm

    def geom_func(X, Y, Z, params):
        M = np.zeros(X.shape, dtype=int)
        M[find_inside_voxels(X, Y, Z, params["file"], A=0.1 * np.eye(3), v=params["v"])] = 1
        return M

    model = stl_model(path, geom_func)
    M = model.G.medium_map()
    X, Y, Z = np.meshgrid(model.G.x, model.G.y, model.G.z, indexing="ij")
    r = np.sqrt(X**2 + Y**2 + (Z - 0.5) ** 2)
    # away from the faceted surface, the map is the analytic ball
    assert np.all(M[r < 0.28] == 1) and np.all(M[r > 0.31] == 0)
    model.G.geom_func_params = {"file": path, "v": (0.0, 0.0, 0.7)}  # a sweep moves the ball
    assert model.G.medium_map()[8, 8, 15] == 1 and M[8, 8, 15] == 0


def test_three_argument_geom_func_still_works_and_misuse_names_the_field():
    model = stl_model(None, lambda X, Y, Z: (Z > 0.5).astype(int))
    model.G.geom_func_params = None
    assert model.G.medium_map().sum() == 16 * 16 * 8
    model.G.geom_func_params = (1, 2)
    with pytest.raises(ValueError, match="G.geom_func_params is set but G.geom_func takes"):
        model.G.medium_map()
    model.G.geom_func = lambda X, Y: X
    with pytest.raises(ValueError, match="G.geom_func must take .* taking 2 arguments"):
        model.G.medium_map()
