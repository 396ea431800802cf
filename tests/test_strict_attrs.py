"""Unknown or misspelled attributes raise at once, naming the closest known name."""

import copy
import pickle
from dataclasses import dataclass

import pytest

from mcmatlab_py import Medium, Model, MonteCarloSimulation, NotBuiltError
from mcmatlab_py._strict import camel_to_snake


def objects():
    model = Model()
    return {"model": model, "G": model.G, "MC": model.MC, "MC.light_source": model.MC.light_source,
            "FMC": model.FMC, "HS": model.HS, "Medium": Medium("t", mua=1.0, mus=10.0)}


@pytest.mark.parametrize("label, typo, suggestion", [
    ("G", "nxx", "nx"),
    ("G", "geom_fun", "geom_func"),
    ("MC", "n_photon_requested", "n_photons_requested"),
    ("MC.light_source", "radious", "radius"),
    ("HS", "durationon", "duration_on"),
    ("Medium", "muaa", "mua"),
    ("model", "HSS", "HS"),
])
def test_misspelled_names_raise_with_the_closest_name(label, typo, suggestion):
    obj = objects()[label]
    with pytest.raises(AttributeError, match=rf"{label} has no attribute '{typo}'; did you mean "
                                             rf"'{suggestion}'\?"):
        setattr(obj, typo, 1)
    assert typo not in vars(obj)
    with pytest.raises(AttributeError, match=f"did you mean '{suggestion}'"):
        getattr(obj, typo)


@pytest.mark.parametrize("label, camel, snake", [
    ("MC", "nPhotonsRequested", "n_photons_requested"),
    ("MC", "boundaryType", "boundary_type"),
    ("MC", "lightSource", "light_source"),
    ("MC.light_source", "xFocus", "x_focus"),
    ("G", "geomFuncParams", "geom_func_params"),
    ("HS", "heatBoundaryType", "heat_boundary_type"),
    ("HS", "Tinitial", "T_initial"),
    ("Medium", "nBins", "n_bins"),
    ("G", "mediaPropertiesFunc", "media"),
    ("MC", "calcNormalizedFluenceRate", "calc_normalized_fluence_rate"),
    ("FMC", "calcNormalizedFluenceRate", "calc_normalized_fluence_rate"),
])
def test_mcmatlab_camel_case_names_point_to_ours(label, camel, snake):
    obj = objects()[label]
    with pytest.raises(AttributeError, match=rf"MCmatlab's {camel} is {label}\.{snake} here"):
        setattr(obj, camel, 1)


def test_mcmatlab_methods_point_to_ours():
    with pytest.raises(AttributeError, match=r"runMonteCarlo is model\.run_monte_carlo\(\) here"):
        Model().runMonteCarlo()


@pytest.mark.parametrize("label, name", [
    ("MC", "interfaceNormals"),
    ("HS", "useAllCPUs"),
    ("Medium", "PY"),
    ("FMC", "CDFs"),
])
def test_mcmatlab_features_not_built_say_so(label, name):
    obj = objects()[label]
    with pytest.raises(NotImplementedError, match=rf"MCmatlab's {label}\.{name} is not built yet"):
        setattr(obj, name, 100)
    with pytest.raises(NotBuiltError):
        getattr(obj, name)
    # also an AttributeError: hasattr and getattr with a default keep working
    assert not hasattr(obj, name)
    assert getattr(obj, name, "default") == "default"


def test_mcmatlab_camel_case_heat_names_point_to_ours():
    HS = objects()["HS"]
    for camel, snake in (("makeMovie", "make_movie"), ("durationEnd", "duration_end")):
        with pytest.raises(AttributeError, match=snake):
            setattr(HS, camel, 1)


def test_broadband_names_point_to_ours():
    """MCmatlab's spectrumFunc (broadband runs, tests/test_broadband.py) is spectrum_func."""
    MC = objects()["MC"]
    with pytest.raises(AttributeError, match=r"MCmatlab's spectrumFunc is MC\.spectrum_func"):
        MC.spectrumFunc = lambda wl: 1.0


def test_fields_private_names_and_copies_work():
    model = Model()
    model.MC.n_photons_requested = 10
    model.MC._scratch = 1  # private names are free
    model.G.geom_func_params = {"depth": 0.1}
    assert copy.deepcopy(model).MC.n_photons_requested == 10
    again = pickle.loads(pickle.dumps(model.MC))
    assert again.n_photons_requested == 10 and again._scratch == 1
    with pytest.raises(AttributeError, match="can't set|has no setter|not writable"):
        model.G.dx = 0.1  # a read-only property stays read-only


def test_new_dataclass_fields_are_picked_up():
    # a field added to a class (as other parts of the port do) is known at once, even
    # where its MCmatlab name is on the not-built list
    @dataclass
    class MC(MonteCarloSimulation):
        n_example_paths: int = 0

    m = MC()
    m.n_example_paths = 5
    assert m.n_example_paths == 5
    with pytest.raises(AttributeError, match="MCmatlab's nExamplePaths is MC.n_example_paths"):
        m.nExamplePaths = 5
    with pytest.raises(AttributeError, match="did you mean 'n_example_paths'"):
        m.n_example_path = 1


@pytest.mark.parametrize("camel, snake", [
    ("nPhotonsRequested", "n_photons_requested"),
    ("GPUdevice", "gpu_device"),
    ("FRinitial", "fr_initial"),
    ("FRdepIterations", "fr_dep_iterations"),
    ("useGPU", "use_gpu"),
    ("x", "x"),
    ("normalizedIrradiance_xpos", "normalized_irradiance_xpos"),
])
def test_camel_to_snake(camel, snake):
    assert camel_to_snake(camel) == snake
