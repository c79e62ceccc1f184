"""What the commands share on the command line: the exit statuses, the options of a command that resolves a
configuration, the output-folder rule (an earlier result is never replaced silently; the folder is locked while
the command runs) and the metric lines of ``run`` and ``replay``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable

from sblsim.fmus.build import DEFAULT_DIR
from sblsim.models.declarations import ModelError, shown
from sblsim.models.sync.identifiability import SURVEY_SIGMA
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cosim.config import take_notes
from sblsim.orchestrator.io.arguments import MAX_SEED
from sblsim.orchestrator.io.output import OutputLock, check_output, folder_name
from sblsim.orchestrator.io.stop import exit_status

#: The exit status of bad input (one line ``sblsim: error: ...``, nothing written); a stopped command's is
#: :func:`interrupted_status`.
EXIT_USAGE = 2


#: --fmu-dir: where the fmu engine looks when it is not given (fmus/build of a checkout, else the user cache).
FMU_DIR_HELP = (f"directory of the built FMUs (default {DEFAULT_DIR}; FMUs missing there are built into the "
                "user cache)")


#: The registered systems (the command line's words: :data:`sblsim.models.systems.SYSTEMS`).
ALL_SYSTEMS = ",".join(SYSTEMS)


def config_options(p: argparse.ArgumentParser) -> None:
    """``--seed``, ``--set`` and ``--fmu-dir``: the options of a command that resolves a configuration."""
    p.add_argument("--seed", type=int, default=None, help="campaign seed (default: from the configuration, 0)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a configuration key, e.g. platform.baseline=3 or receiver=lsq (repeatable)")
    p.add_argument("--fmu-dir", type=Path, default=None, help=FMU_DIR_HELP)


def check_seed_option(seed: int | None) -> None:
    """``--seed`` (an integer already: argparse's ``type=int``) in [0, MAX_SEED]."""
    if seed is not None and not 0 <= seed <= MAX_SEED:
        raise ModelError(f"--seed: {shown(seed)} is outside the allowed range [0, {MAX_SEED}]")


def interrupted_status() -> int:
    """The exit status of a stopped command: 128 + the signal that stopped it (Ctrl-C 130, SIGTERM 143, SIGHUP 129;
    :func:`sblsim.orchestrator.io.stop.exit_status`)."""
    return exit_status()


#: The output folders this command holds locked (released when it ends).
LOCKS: list[OutputLock] = []


def output_folder(given: Path | None, default: Path, force: bool, marker: str, what: str,
                  before: Callable[[Path], None] | None = None) -> Path:
    """The output folder of a command: ``--out`` as given, or the default folder.

    An earlier result is never replaced silently. A folder given with ``--out`` that holds one (its
    ``marker`` file) needs ``--force``; the default folder, when it holds one, is kept and the next free
    numbered folder beside it is used (``results/semicircle-2``), said on the command line, so that the
    documented commands run one after the other. Checked before any work (:func:`check_output`, then
    ``before(out)``). The folder is then locked until the command ends
    (:class:`sblsim.orchestrator.io.output.OutputLock`): a second command into it meanwhile is refused.
    """
    if given is not None or force or not (default / marker).exists():
        out = given or default
    else:
        out = next(default.with_name(f"{default.name}-{k}") for k in range(2, 1_000_000)
                   if not (default.with_name(f"{default.name}-{k}") / marker).exists())
        print(f"note: {default}/ holds an earlier {what} (kept); writing to {out}/ (--out DIR to choose, --force "
              "to replace)", file=sys.stderr)
    check_output(out, force, marker, what)
    if before is not None:
        before(out)
    LOCKS.append(OutputLock(out).acquire())
    print_notes()  # every input read and checked: what the configurations left unused
    return out


def add_refinement(p: argparse.ArgumentParser, what: str) -> None:
    """``--refine-positions`` (``what`` it refines them with) and ``--survey-sigma`` (its prior)."""
    p.add_argument("--refine-positions", action="store_true",
                   help=f"refine the receivers' horizontal positions {what} (a prior of --survey-sigma at the "
                        "table's); writes positions.csv")
    p.add_argument("--survey-sigma", type=float, default=None, metavar="M",
                   help=f"the table's horizontal sigma per axis [m]: with --refine-positions its prior in [0.01, "
                        f"1000] (default {SURVEY_SIGMA:g}: a handheld GPS's); without, the survey's stated error in "
                        "every sigma, in [0, 1000] (0: the positions taken as exact; default: the error the "
                        "synchronisation's residuals show where seen, else exact)")


def add_receivers(p: argparse.ArgumentParser, required: bool = True) -> None:
    """``--receivers``, ``--crs``, ``--frame``: a study's receivers and where they are (``--receivers`` optional
    where the command finds them otherwise: ``sblsim track``'s actel workspace)."""
    p.add_argument("--receivers", type=Path, required=required, metavar="FILE",
                   help="the receivers: serial,sync_tag,x_m,y_m[,z_m], or deployments with lat,lon and dates (GLATOS "
                        "receiver_locations and OTN deployments' names: ins_serial_no, deploy_lat, deploy_long, "
                        "deploy_date_time, recover_date_time, instrument_depth, transmitter)")
    p.add_argument("--crs", default=None, metavar="EPSG",
                   help="the receivers' CRS (default WGS 84 for lat,lon; a projected one for x_m,y_m)")
    p.add_argument("--frame", default=None, metavar="EPSG",
                   help="the metric frame lat,lon are projected to (default: the UTM zone of the array's centre)")


def print_notes() -> None:
    """The notes of the configurations read so far (:func:`sblsim.orchestrator.cosim.config.take_notes`), one
    ``note:`` line each on standard error."""
    for line in take_notes():
        print(f"note: {line}", file=sys.stderr)


def output_name(scenario: str) -> str:
    """The name a default output folder takes from a scenario argument: a file's stem, a built-in's name (any
    character that is not a plain file-name character replaced: :func:`sblsim.orchestrator.io.output.folder_name`)."""
    return folder_name(Path(scenario).stem if scenario.endswith(".toml") else Path(scenario).name)


def print_metrics(s: dict, truth: bool = True) -> None:
    """The metric lines of ``run`` and ``replay`` from a summary (``n/a`` for a metric without a value)."""
    def v(key: str, spec: str = ".3f", scale: float = 1.0) -> str:
        return "n/a" if s[key] is None else format(scale * s[key], spec)

    label = f"{s['receiver']}:"
    width = max(len(label), len("instrumentation:")) + 1
    if truth:
        print(f"  {label:<{width}}e_tot mean {v('e_tot_mean')} m, RMS {v('e_tot_rms')} m, std {v('e_tot_std')} m")
        print(f"  {'instrumentation:':<{width}}e_tot mean {v('instr_e_tot_mean')} m, "
              f"RMS {v('instr_e_tot_rms')} m, std {v('instr_e_tot_std')} m")
        print(f"  {'consistency:':<{width}}NEES {v('nees_mean', '.2f')} (3 if consistent), truth inside the 95 % "
              f"ellipsoid {v('coverage_95', '.1f', 100)} % of steps, mean NIS {v('nis_mean', '.2f')}, "
              f"gated {v('gated_pct', '.1f')} % of ranges")
        print(f"  {'accuracy limit:':<{width}}PCRB RMS {v('pcrb_rms')} m")
    else:
        print(f"  {label:<{width}}no truth track (--truth FILE for errors and consistency): {s['updates']} "
              f"updates, {s['fix_steps']} steps with a multilateration fix, mean NIS {v('nis_mean', '.2f')}, "
              f"gated {v('gated_pct', '.1f')} % of ranges")
