"""The paper's synthetic experiments (Arnold & Fichera, section "Results"), end to end.

* The truth: the paper's block (0.5 x 0.5 x 0.25 cm, 100 x 100 x 50 voxels, standard
  tissue), a 1 mm top-hat beam of 0.5 W for 5 s then 10 s off, initial temperature
  0 deg C; Monte Carlo for the absorbed power (direct, at every change of the optical
  properties) and FEM heat on the fine mesh. Sensor at (0, 0, 0) read at 10 Hz with
  Gaussian noise of variance 0.01.
* The filter: N = 50 members on the coarse 20 x 20 x 10 model, absorbed power from the
  emulator. The analysis is the deterministic ETKF by default: on the paper's constant
  case it met every target on five seeds of five, the perturbed-observation EnKF of the
  paper (``method="enkf"``, ``--method enkf``) on three (validation/reports/paper_runs.md).

Where the paper is silent we do what MCmatlab does by default, and say so:
matched interfaces (``matchedInterfaces = true``: no Fresnel reflection at the
cuboid faces), boundary type 1 (photons escape through every face), insulating
heat boundaries (``heatBoundaryType = 0``), backward-Euler steps of 0.1 s (one per
sensor reading), and 10^7 photons for a constant-property map, 5 x 10^5 per step
while the properties ramp.

Modules: :mod:`~enkf.paper.scenarios` (Table 1, lasers, true optics, the MCmatlab-style
model), :mod:`~enkf.paper.truth` (fine-grid and twin truths, the noisy sensor),
:mod:`~enkf.paper.runner` (the filter of each scenario, one experiment end to end),
:mod:`~enkf.paper.sensitivity`, :mod:`~enkf.paper.figures`, and, beyond the paper,
:mod:`~enkf.paper.coagulation` (tissue whose optics follow its damage: its truths and
filters). The paper uses the application (:mod:`enkf.tissue`), never the tool (:mod:`enkf.app`).
"""

from .figures import plot_data, plot_results, plot_sensitivity
from .filters import emulator_for, filter_setup
from .runner import PaperRun, paper_advice, run_experiment, summarize, write_run
from .scenarios import (
    CAMERA,
    PULSES,
    SCENARIOS,
    TABLE,
    camera_image,
    heating_time,
    mua_ramp,
    mus_ramp,
    paper_model,
    train_optics,
    true_parameters,
)
from .sensitivity import sensitivity_study
from .truth import Truth, TruthConfig, generate_truth, noisy_sensor, twin_truth

__all__ = [
    "CAMERA",
    "PULSES",
    "SCENARIOS",
    "TABLE",
    "PaperRun",
    "Truth",
    "TruthConfig",
    "camera_image",
    "emulator_for",
    "filter_setup",
    "generate_truth",
    "heating_time",
    "mua_ramp",
    "mus_ramp",
    "noisy_sensor",
    "paper_model",
    "plot_data",
    "plot_results",
    "plot_sensitivity",
    "paper_advice",
    "run_experiment",
    "sensitivity_study",
    "summarize",
    "train_optics",
    "true_parameters",
    "twin_truth",
    "write_run",
]
