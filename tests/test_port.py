"""tissue-enkf port: MCmatlab model scripts to Python (mcmatlab_py.port).

The models here are written for these tests in MCmatlab's style (none of MCmatlab's own
files is kept in this repository); validation/port_examples.py converts and runs
MCmatlab's 27 examples.
"""

from __future__ import annotations

import runpy

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

pytest.importorskip("miss_hit_core")

from enkf.app.cli import main  # noqa: E402
from mcmatlab_py.port import MatlabSyntaxError, ParserMissingError, port_model  # noqa: E402

#: a skin model edited from the shape of MCmatlab's examples: a gel layer, epidermis, dermis
#: with a vessel and a saturable absorber, media by numbers, handles and calc_mua/calc_mus,
#: a top-hat beam, MC.P before the heat run
SKIN = r"""%% A model of my own, in MCmatlab's style
model = MCmatlab.model;

model.G.nx                = 20; % bins in x
model.G.ny                = 18;
model.G.nz                = 16;
model.G.Lx                = .1; % [cm]
model.G.Ly                = .1;
model.G.Lz                = .08;
model.G.mediaPropertiesFunc = @mediaPropertiesFunc;
model.G.geomFunc          = @geometryDefinition;
model = plot(model,'G');

%% Monte Carlo
model.MC.nPhotonsRequested        = 3000;
model.MC.matchedInterfaces        = true;
model.MC.boundaryType             = 1;
model.MC.wavelength               = 585;
model.MC.LS.sourceType            = 4;
model.MC.LS.FPID.radialDistr      = 0;
model.MC.LS.FPID.radialWidth      = .02;
model.MC.LS.AID.radialDistr       = 0;
model.MC.LS.AID.radialWidth       = 0;
model.MC.depositionCriteria.minMediumIdxToConsider = 2;
model = runMonteCarlo(model);
model = plot(model,'MC');
absorbed = sum(model.MC.NA(:))*model.G.dx*model.G.dy*model.G.dz;
fprintf('absorbed %.4f\n', absorbed);

%% Heat
model.MC.P                   = 3; % [W]
model.HS.durationOn          = 0.001;
model.HS.durationOff         = 0.0;
model.HS.durationEnd         = 0.001;
model.HS.T                   = 37;
model.HS.nPulses             = 1;
model.HS.nUpdates            = 2;
model.HS.tempSensorPositions = [0 0 0.03
                                0 0 0.05];
model = simulateHeatDistribution(model);
set(gca,'FontSize',18);

function M = geometryDefinition(X,Y,Z,parameters)
  zsurf = 0.01;
  M = ones(size(X)); % gel
  M(Z > zsurf) = 2; % epidermis
  M(Z > zsurf + 0.006) = 3; % dermis
  M(sqrt(X.^2 + (Z - 0.04).^2) < 0.01 & ~(Y > 0.04)) = 4; % vessel, not at the far side
  M(:,:,end) = 3;
end

function mediaProperties = mediaPropertiesFunc(parameters)
  mediaProperties = MCmatlab.mediumProperties;
  j=1;
  mediaProperties(j).name  = 'gel';
  mediaProperties(j).mua   = 0.0004;
  mediaProperties(j).mus   = 10;
  mediaProperties(j).g     = 1;
  mediaProperties(j).VHC   = 4.19;
  mediaProperties(j).TC    = 5.8e-3;
  j=2;
  mediaProperties(j).name  = 'epidermis';
  mediaProperties(j).mua   = @(wavelength) calc_mua(wavelength,0.75,0,0.75,0,0.03);
  mediaProperties(j).mus   = @mus2;
  function mus = mus2(wavelength)
    mus = calc_mus(wavelength,40,0,1,0.9);
  end
  mediaProperties(j).g     = 0.9;
  mediaProperties(j).VHC   = 3.76;
  mediaProperties(j).TC    = 0.37e-2;
  j=3;
  mediaProperties(j).name  = 'dermis';
  mediaProperties(j).mua   = 2;
  mediaProperties(j).mus   = 200;
  mediaProperties(j).g     = 0.9;
  mediaProperties(j).VHC   = 3.76;
  mediaProperties(j).TC    = 0.37e-2;
  j=4;
  mediaProperties(j).name  = 'blood that bleaches';
  mediaProperties(j).mua   = @(wavelength,FR,T,FD) 200./(1 + FR/1e4);
  mediaProperties(j).mus   = 100;
  mediaProperties(j).g     = 0.9;
  mediaProperties(j).VHC   = 3.8;
  mediaProperties(j).TC    = 0.52e-2;
  mediaProperties(j).nBins = 4;
end
"""


@pytest.fixture
def quick(monkeypatch):
    monkeypatch.setenv("MCMATLAB_PY_QUICK", "1")


def test_own_model_converts_and_runs(tmp_path, quick):
    result = port_model(SKIN, "skin.m")
    script = result.script
    # settings in snake_case, media 0-based, MC.P of a heat run is HS.P
    assert "model.MC.light_source.focal_plane_intensity_distribution.radial_width = 0.02" \
        in script
    assert "model.HS.P = 3" in script and "model.MC.P" not in script
    assert "min_medium_idx_to_consider = 1" in script
    assert "model.HS.T_initial = model.MC.T = 37" in script
    assert "M = np.zeros(X.shape, dtype=int)" in script and "M[:, :, -1] = 2" in script
    assert "lambda wavelength, FR, T, FD: 200 / (1 + FR / 1e4)" in script
    # the figure-styling line is kept as a comment and listed with its line number
    (line, text, why), = result.unconverted
    assert SKIN.splitlines()[line - 1].startswith("set(gca")
    assert "set(gca,'FontSize',18);" in text and "style" in why
    assert f"# MATLAB (line {line}, not converted" in script
    path = tmp_path / "skin.py"
    path.write_text(script)
    ns = runpy.run_path(str(path), run_name="__main__")
    model = ns["model"]
    assert [m.name for m in model.G.media] == ["gel", "epidermis", "dermis",
                                                "blood that bleaches"]
    # the voxel map, 0-based, computed here from the model's own rules
    G = model.G
    X, Y, Z = np.meshgrid(G.x, G.y, G.z, indexing="ij")
    want = np.zeros(X.shape, dtype=int)
    want[Z > 0.01] = 1
    want[Z > 0.016] = 2
    want[(np.sqrt(X**2 + (Z - 0.04) ** 2) < 0.01) & ~(Y > 0.04)] = 3
    want[:, :, -1] = 2
    np.testing.assert_array_equal(G.medium_map(), want)
    assert model.MC.NA.shape == (20, 18, 16)
    # the script's sum(NA(:))*dV; with deposition criteria NA holds only the deposits that
    # met them (MC.absorbed_fraction counts all, for the energy balance)
    assert ns["absorbed"] == pytest.approx(model.MC.NA.sum() * G.dx * G.dy * G.dz, rel=1e-9)
    assert model.HS.P == 3 and model.HS.sensor_temps.shape[1] == 2
    assert np.all(model.HS.sensor_temps[-1] >= 37.0 - 1e-9)


def test_expressions_and_indexing():
    src = """x = linspace(0, 1, 5);
y = zeros(1, length(x));
for i = 1:length(x)
  y(i) = x(i).^2 + 2^-1;
end
A = [1 2; 3 4];
B = A*A';
z = x(2:end-1);
w = x(end:-1:1);
s = sum(y(:));
t = ~isempty(z) && numel(z) == 3;
c = {x(1)};
d = c{1};
"""
    script = port_model(src, "e.m").script
    assert "for i in range(1, len(x) + 1):" in script
    assert "y[i - 1] = x[i - 1] ** 2 + 2 ** (-1)" in script
    assert "B = A @ np.transpose(A)" in script
    assert "z = x[1:-1]" in script
    ns = {}
    exec(compile(script, "e.py", "exec"), ns)  # noqa: S102 - the converted script under test
    np.testing.assert_allclose(ns["y"], np.linspace(0, 1, 5) ** 2 + 0.5)
    np.testing.assert_array_equal(ns["B"], np.array([[5, 11], [11, 25]]))
    np.testing.assert_allclose(ns["z"], [0.25, 0.5, 0.75])
    np.testing.assert_allclose(ns["w"], np.linspace(1, 0, 5))
    assert ns["s"] == pytest.approx(sum(np.linspace(0, 1, 5) ** 2 + 0.5))
    assert ns["t"] is True and ns["d"] == 0.0


def test_matlab_values_are_copied():
    src = """model1 = MCmatlab.model;
model1.MC.P = 1;
model2 = model1;
model2.MC.P = 0.2;
"""
    ns = {}
    exec(compile(port_model(src).script, "c.py", "exec"), ns)  # noqa: S102
    assert (ns["model1"].MC.P, ns["model2"].MC.P) == (1, 0.2)


def test_linear_index_is_column_major():
    src = """function M = g(X,Y,Z,parameters)
  [nx,ny,~] = size(X);
  M = ones(size(X));
  M(1:(nx*(ny+1)+1):end) = 2;
end
"""
    ns = {}
    exec(compile(port_model(src).script, "g.py", "exec"), ns)  # noqa: S102
    X = np.zeros((4, 4, 4))
    M = ns["g"](X, X, X, None)
    assert np.array_equal(np.argwhere(M == 2), [[k, k, k] for k in range(4)])


def test_mask_with_an_inner_end_stays_a_mask():
    # MCmatlab Example 17's droplet: Z(end) is Z's last element, the subscript a mask of M
    src = """model = MCmatlab.model;
model.G.geomFunc = @g;

function M = g(X,Y,Z,parameters)
  M = ones(size(X));
  M(X.^2 + (Z - Z(end)).^2 < 1.5) = 2;
end
"""
    script = port_model(src).script
    assert "M[X ** 2 + (Z - Z.T.flat[-1]) ** 2 < 1.5] = 1" in script
    ns = {}
    exec(compile(script, "g.py", "exec"), ns)  # noqa: S102
    X, Y, Z = np.meshgrid(np.arange(3.0), np.arange(2.0), np.arange(4.0), indexing="ij")
    np.testing.assert_array_equal(ns["g"](X, Y, Z, None), X**2 + (Z - 3) ** 2 < 1.5)  # 0-based


def test_unmatched_interfaces_keep_mcmatlabs_faces():
    # MCmatlab's cuboid faces neither reflect nor refract: MC.n_outside = None
    src = "model = MCmatlab.model;\nmodel.MC.matchedInterfaces = false; % Fresnel inside\n"
    ns = {}
    script = port_model(src).script
    assert "model.MC.matched_interfaces = False  # Fresnel inside" in script
    exec(compile(script, "f.py", "exec"), ns)  # noqa: S102
    assert ns["model"].MC.n_outside is None and ns["model"].MC.matched_interfaces is False


#: MCmatlab 3's style (Test1's): properties as text of FR and T, a power yield, Tinitial
OLD_STYLE = """model = MCmatlab.model;
model.G.nx = 9; model.G.ny = 9; model.G.nz = 8;
model.G.Lx = .1; model.G.Ly = .1; model.G.Lz = .1;
model.G.mediaPropertiesFunc = @mediaPropertiesFunc;
model.G.geomFunc = @geometryDefinition;
model = reset(model,'MC'); % a fresh MC
model.MC.nPhotonsRequested = 500;
model.MC.wavelength = 532;
model.MC.P = 2;
model.HS.Tinitial = 3;
model = runMonteCarlo(model);
model.FMC.nPhotonsRequested = 500;
model.FMC.wavelength = 600;
model = runMonteCarlo(model,'fluorescence');

function M = geometryDefinition(X,Y,Z,parameters)
M = ones(size(X));
end

function mediaProperties = mediaPropertiesFunc(wavelength,parameters)
j=1;
mediaProperties(j).name = 'material 1';
mediaProperties(j).mua  = '1 + (T+FR)/100';
mediaProperties(j).mus  = 10;
mediaProperties(j).g    = 0.9;
mediaProperties(j).PY   = '0.5/(1+T/10)';
end
"""


def test_mcmatlab3_model(quick):
    result = port_model(OLD_STYLE, "old.m")
    assert result.unconverted == []
    script = result.script
    # the start temperature is what the Monte Carlo sees; FR in the text: 20 iterations
    # (MCmatlab 3's FRdepIterations), set again after reset; PY as photons
    assert "model.HS.T_initial = model.MC.T = 3" in script
    assert script.count("model.MC.fr_dep_iterations = 20") == 2
    assert 'model = model.reset("MC")  # a fresh MC\nquick(model)\n' in script
    ns = {}
    exec(compile(script, "old.py", "exec"), ns)  # noqa: S102
    model = ns["model"]
    assert model.MC.fr_dep_iterations == 20 and model.MC.n_photons <= 500
    QY = model.G.media[0].QY
    assert QY(532.0, 0.0, 3.0, 0.0) == pytest.approx(0.5 / 1.3 * 600 / 532, rel=1e-12)
    # the fluorescence emitted is PY times the absorbed power
    dV = model.G.dx * model.G.dy * model.G.dz
    assert model.FMC.emitted_power == pytest.approx(
        0.5 / 1.3 * model.MC.NA.sum() * dV, rel=1e-9)


def test_unknown_function_is_kept_and_listed():
    result = port_model("a = 1;\nb = myHelper(a);\nc = a + 1;\n")
    assert result.unconverted[0][0] == 2 and "myHelper" in result.unconverted[0][2]
    assert "c = a + 1" in result.script


def test_syntax_error_names_the_line():
    with pytest.raises(MatlabSyntaxError, match="line 2"):
        port_model("a = 1;\nb = (2 + ;\n")


def test_command_line(tmp_path, capsys):
    model = tmp_path / "skin.m"
    model.write_text(SKIN)
    out = tmp_path / "skin.py"
    assert main(["port", str(model), "-o", str(out)]) == 0
    assert "model.G.geom_func = geometryDefinition" in out.read_text()
    err = capsys.readouterr().err
    assert "1 statement kept as comments" in err and "set(gca" in err
    assert main(["port", str(model), "-o", str(out)]) == 2  # exists, no --force
    assert "exists" in capsys.readouterr().err
    assert main(["port", str(tmp_path / "missing.m")]) == 2
    assert "'" + str(tmp_path / "missing.m") + "' is not a file" in capsys.readouterr().err
    assert main(["port", str(out)]) == 2
    assert "must be a MATLAB script" in capsys.readouterr().err


def test_missing_parser_says_how_to_install(tmp_path, capsys, monkeypatch):
    import mcmatlab_py.port.parse as parse

    def missing():
        raise ParserMissingError(parse.INSTALL_HINT)

    monkeypatch.setattr(parse, "_miss_hit", missing)
    model = tmp_path / "a.m"
    model.write_text("a = 1;\n")
    assert main(["port", str(model)]) == 2
    assert "pip install 'tissue-enkf[port]'" in capsys.readouterr().err
