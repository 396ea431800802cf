"""The ``tissue-enkf`` command line (an edge module).

Every subcommand validates its input first; a problem with the input prints one
line ``error: ...`` naming it and exits with status 2, writing nothing.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import warnings

from fem.checks import check_number

from .. import __version__
from .cmd_identify import cmd_identify
from .cmd_model import cmd_heat, cmd_mc
from .cmd_paper import cmd_paper
from .cmd_port import cmd_port
from .cmd_replay import cmd_replay
from .cmd_validate import cmd_validate
from .common import EXIT_BAD_INPUT, EXIT_UNEXPECTED, MAX_SEED, shorten

__all__ = ["build_parser", "main"]


class _Parser(argparse.ArgumentParser):
    """argparse's parser, whose option errors are one line that names the command, the
    option and the value, not the usage of every option (exit status 2). The
    subcommands' parsers are of this class too (argparse makes them of the parent's)."""

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"error: {self.prog}: {shorten(' '.join(message.split()), 240)}"
                                  f" (see {self.prog} --help)\n")


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, help="output directory (created; must be new or empty)")
    p.add_argument("--force", action="store_true", help="replace a non-empty --out")
    p.add_argument("--seed", type=int, default=None, help="random seed (overrides the config)")
    p.add_argument("--threads", type=int, default=None, help="numba threads (default: all cores)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bars (the result line is still printed)")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                   help="show the traceback of an error instead of one line")


def _dask_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("Dask (pip install \"tissue-enkf[dist]\")")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the Monte Carlo tasks on an existing Dask cluster "
                        "(e.g. tcp://10.0.0.5:8786)")
    g.add_argument("--workers", type=int, default=None, metavar="N",
                   help="run them on a new local Dask cluster of N single-threaded workers")


def _model_command(p: argparse.ArgumentParser, config_help: str, func) -> None:
    """The arguments of the commands that run a TOML model (mc, heat)."""
    p.add_argument("config", help=config_help)
    p.add_argument("--photons", type=int, default=None,
                   help="number of photon packets (overrides MC.n_photons_requested)")
    _common(p)
    _dask_options(p)
    p.set_defaults(func=func)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="tissue-enkf",
        description="Monte Carlo light transport, FEM heat and ensemble Kalman filtering "
                    "for laser-irradiated tissue.")
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an error instead of one line")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    p_mc = sub.add_parser("mc", help="run the Monte Carlo of a TOML model",
                          description="Run MCmatlab-style Monte Carlo light transport for the "
                                      "model in CONFIG and write NA/NFR (.npz, .vtu), "
                                      "summary.json and a PNG of NA slices.")
    _model_command(p_mc, "TOML model file (see examples/)", cmd_mc)

    p_paper = sub.add_parser(
        "paper", help="run one of the paper's experiments end to end",
        description="Fine-grid truth (Monte Carlo + FEM heat), noisy sensor data, and the "
                    "EnKF on the coarse model with the absorption emulator; writes "
                    "estimates.csv, truth.csv, summary.json and figures/.")
    p_paper.add_argument("scenario", choices=("constant", "time-varying", "all-params",
                                              "pulse-train", "sensitivity"),
                         help="an experiment ('pulse-train': three pulses, optics that change "
                              "while heated, beyond the paper), or 'sensitivity' for the "
                              "paper's sensitivity study")
    p_paper.add_argument("--members", type=int, default=50, help="ensemble size N (default 50)")
    p_paper.add_argument("--drift", choices=("paper", "auto"), default="paper",
                         help="'paper' (default): the scenario's own random walk, chosen "
                              "knowing whether its optics drift; 'auto': identify's default, "
                              "a still and a drifting filter weighed by the data")
    p_paper.add_argument("--method", choices=("enkf", "etkf"), default="etkf",
                         help="analysis: deterministic ETKF (default) or the paper's EnKF "
                              "with perturbed observations")
    p_paper.add_argument("--fine", type=int, nargs=3, default=(100, 100, 50),
                         metavar=("NX", "NY", "NZ"), help="truth grid (default 100 100 50)")
    p_paper.add_argument("--truth-photons", type=int, default=None,
                         help="photons of the truth's Monte Carlo (per step when the optics "
                              "change; default 1e7 constant, 5e5 per step)")
    p_paper.add_argument("--emulator-photons", type=int, default=250_000,
                         help="photons per emulator table point at mus = 100 (default 2.5e5)")
    p_paper.add_argument("--emulator-table", type=int, default=12, metavar="N",
                         help="N x N log-spaced (mua, mus) table points (default 12)")
    p_paper.add_argument("--exact", action="store_true",
                         help="direct Monte Carlo per member and step instead of the emulator "
                              "(slow: for checking)")
    p_paper.add_argument("--cache-dir", default=None,
                         help="where emulator tables and truths are cached "
                              "(default $TISSUE_ENKF_CACHE or ~/.cache/tissue-enkf)")
    _common(p_paper)
    _dask_options(p_paper)
    p_paper.set_defaults(func=cmd_paper)
    p_heat = sub.add_parser(
        "heat", help="Monte Carlo plus heat: sensor series and volume fields",
        description="Run the Monte Carlo of the model in CONFIG, then the heat simulation of "
                    "its [HS] table (laser pulses, boundaries, sensors); write sensors.csv "
                    "(temperature at HS.temp_sensor_positions), summary.json, figures/ and "
                    "fields/*.vtu (temperature, damage on the mesh; NA, NFR on the voxels).")
    _model_command(p_heat, "TOML model file with [G], [MC] and [HS] (see examples/)", cmd_heat)

    p_id = sub.add_parser(
        "identify", help="the filter on measured data",
        description="Estimate the optical properties (and the temperatures below the "
                    "surface) from measured temperatures: the model, sensors and filter come "
                    "from CONFIG, the data from a CSV (a header; time in s, then one column "
                    "per sensor in deg C in the order of sensors.positions, or the columns "
                    "named by data.columns; irregular times; gaps empty or nan) or an NPZ "
                    "thermal image series (times, frames; with [sensors.camera]). Writes "
                    "estimates.csv, summary.json, "
                    "figures/, fields/final.vtu and run.json. Several --data files run as a "
                    "batch (one Dask task each with --workers/--scheduler) and add batch.csv. "
                    "Exit status 0 (also when the filter's health check stopped a run: "
                    "summary.json says when and why, the estimates up to then are written), "
                    "1 when every file of a batch failed (batch.csv says why), 2 for bad "
                    "input. --follow: a file replaced or truncated while followed is read "
                    "again from its start (header first) after a warning; Ctrl-C keeps the "
                    "estimates written so far.")
    p_id.add_argument("config", help="TOML file: [G], [MC], [HS], [sensors], [filter], [data] "
                                      "(see examples/own_data.toml, docs/cli.md)")
    p_id.add_argument("--data", nargs="+", default=None, metavar="FILE",
                      help="measured data: CSV or NPZ file(s) (default: data.file of the config)")
    p_id.add_argument("--follow", default=None, metavar="FILE",
                      help="online: read FILE as the acquisition appends to it, write each "
                           "estimate before the next frame (stops at '# end' or when idle)")
    p_id.add_argument("--idle-timeout", type=float, default=10.0,
                      help="--follow: stop after this many seconds without a new line "
                           "(a finite number > 0; default 10)")
    p_id.add_argument("--serve", type=int, nargs="?", const=5006, default=None, metavar="PORT",
                      help="--follow: a live page at http://127.0.0.1:PORT/ (default 5006; 0 "
                           "a free port): the frame, the optics, the temperatures beneath, "
                           "the damage risk; it stays after the run until Ctrl-C (needs "
                           "bokeh: pip install \"tissue-enkf[camera]\")")
    p_id.add_argument("--cache-dir", default=None, help="emulator cache directory")
    _common(p_id)
    _dask_options(p_id)
    p_id.set_defaults(func=cmd_identify)

    p_rep = sub.add_parser(
        "replay", help="the live page over a recorded run",
        description="Serve the page of identify --follow --serve over a finished run "
                    "directory: its estimates revealed at the data's pace (or --speed times "
                    "it), the frames of its camera files, the recorded damage-risk map. "
                    "Until Ctrl-C.")
    p_rep.add_argument("run_dir", metavar="RUN_DIR", help="an identify run's --out")
    p_rep.add_argument("--port", type=int, default=5006,
                       help="http://127.0.0.1:PORT/ (default 5006; 0 a free port)")
    p_rep.add_argument("--speed", type=float, default=1.0,
                       help="times the data's own pace (default 1)")
    p_rep.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="show the traceback of an error instead of one line")
    p_rep.set_defaults(func=cmd_replay)

    p_val = sub.add_parser(
        "validate", help="run the validation suite and write a Markdown report",
        description="Run the validation scripts of the source tree (validation/*.py), each "
                    "in its own process, and collect their reports and figures into "
                    "--out/report.md. --quick (default) runs small versions in a few "
                    "minutes; --full the published sizes (hours). Exit status 0 when every "
                    "check ran, 1 when one failed (the report says which), 2 for bad input.")
    size = p_val.add_mutually_exclusive_group()
    size.add_argument("--quick", dest="full", action="store_false",
                      help="small versions, a few minutes (default)")
    size.add_argument("--full", dest="full", action="store_true",
                      help="the published sizes (can take hours)")
    p_val.add_argument("--only", nargs="+", default=None, metavar="CHECK",
                       help="run only these checks (names of validation/*.py, or "
                            "'sensitivity')")
    p_val.set_defaults(full=False)
    _common(p_val)
    p_val.set_defaults(func=cmd_validate)

    p_port = sub.add_parser(
        "port", help="convert a MCmatlab model script (.m) into a Python script",
        description="Convert a MCmatlab model script into a Python script that uses "
                    "mcmatlab_py (docs/porting.md); the lines it cannot convert are kept as "
                    "comments and listed on stderr. Needs the MATLAB parser: pip install "
                    "'tissue-enkf[port]'.")
    p_port.add_argument("model", metavar="MODEL.m", help="the MCmatlab model script")
    p_port.add_argument("-o", "--output", default=None, metavar="OUT.py",
                        help="write the script here (default: standard output)")
    p_port.add_argument("--force", action="store_true", help="replace an existing OUT.py")
    p_port.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                        help="show the traceback of an error instead of one line")
    p_port.set_defaults(func=cmd_port)
    return parser


#: the signals that end a run as Ctrl-C does: kill's default, a closed terminal or SSH
#: connection, Ctrl-\ (whose default, a core dump, would leave the partial outputs behind)
TERMINATING_SIGNALS = (signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT)


class Terminated(BaseException):
    """A terminating signal arrived: unwind like Ctrl-C (partial outputs are removed on the
    way out); ``signum`` is the signal's number."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__(signum)
        self.signum = signum


def _on_signal(signum, frame):
    raise Terminated(signum)


def main(argv=None) -> int:
    """Run ``tissue-enkf``; returns the exit status.

    0 success; 1 a validation check failed, or an unexpected error (one line and a hint
    to report it; ``--debug`` shows the traceback); 2 bad input (one line naming the
    field and the value, nothing written); 130 Ctrl-C, 143 SIGTERM, 129 SIGHUP and 131
    SIGQUIT (partial outputs removed).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    from . import report

    report.command_line = ["tissue-enkf", *(sys.argv[1:] if argv is None else argv)]
    if not args.debug:  # a warning is one line for the user, not a source excerpt
        warnings.formatwarning = lambda message, *a, **k: f"warning: {message}\n"
    old, old_int = {}, None
    if threading.current_thread() is threading.main_thread():
        old = {s: signal.signal(s, _on_signal) for s in TERMINATING_SIGNALS}
        # Ctrl-C raises KeyboardInterrupt (exit 130, what was kept said) even when a library
        # imported earlier in this process (a Dask cluster, a notebook) replaced the handler
        old_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        seed = getattr(args, "seed", None)
        if seed is not None:
            check_number("--seed", seed, integer=True, lo=0, hi=MAX_SEED)
        return args.func(args)
    except KeyboardInterrupt as exc:  # `outcome`: what a command kept (identify --follow)
        print(f"interrupted: {getattr(exc, 'outcome', 'nothing written')}", file=sys.stderr)
        return 130
    except Terminated as exc:
        print(f"terminated ({signal.Signals(exc.signum).name}): "
              f"{getattr(exc, 'outcome', 'nothing written')}", file=sys.stderr)
        return 128 + exc.signum  # the shell's status of a process the signal ended
    except (ValueError, OSError) as err:
        if args.debug:
            raise
        msg = str(err).splitlines()[0] if str(err) else type(err).__name__
        # values are cut where a message is made (shorten); this catches the rest
        print(f"error: {shorten(msg, 400)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as err:  # noqa: BLE001 - the last line of defence: one line, not a traceback
        if args.debug:
            raise
        first = str(err).splitlines()[0] if str(err) else ""
        print(f"error: unexpected {type(err).__name__}: {shorten(first)}"
              f"\nThis is a bug in tissue-enkf: please report it with the command line and "
              f"--debug's traceback.", file=sys.stderr)
        return EXIT_UNEXPECTED
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
        if old_int is not None:
            signal.signal(signal.SIGINT, old_int)


if __name__ == "__main__":
    sys.exit(main())
