"""``sblsim ssp export``: the system as an SSP 1.0 package (SystemStructure.ssd, the FMUs and the parameter
sets) for other FMI hosts (:mod:`sblsim.orchestrator.cosim.ssp`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sblsim.fmus.build import FMI_VERSIONS
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.commands.common import resolve_plan
from sblsim.orchestrator.commands.console import check_seed_option, config_options
from sblsim.orchestrator.cosim.ssp import export_ssp
from sblsim.orchestrator.io.output import check_writable

NAME = "ssp"
HELP = "export the system as an SSP 1.0 package for other FMI hosts"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim ssp``'s arguments."""
    ssub = p.add_subparsers(dest="ssp_command", required=True, parser_class=type(p))
    e = ssub.add_parser("export", help="write SystemStructure.ssd, the FMUs and the parameter sets as FILE.ssp")
    e.add_argument("scenario", help="built-in scenario or CONFIG.toml")
    e.add_argument("--out", type=Path, required=True, help="the .ssp file to write")
    e.add_argument("--force", action="store_true", help="replace an existing package")
    e.add_argument("--fmi-version", type=int, choices=FMI_VERSIONS, default=2,
                   help="2 (default): the built FMI 2.0 FMUs; 3: the scenario's FMI 3.0 FMUs, built for the "
                        "package with its parameters as start values (docs/interop.md, FMI 3.0)")
    config_options(e)


def main(args: argparse.Namespace) -> int:
    """``sblsim ssp`` from its parsed arguments: its lines printed, its exit status returned."""
    check_seed_option(args.seed)
    cfg = resolve_plan(args.scenario, args.seed, args.overrides)  # the export's one resolution
    check_writable(args.out.parent if str(args.out.parent) else Path("."))
    if args.out.is_dir():
        raise ModelError(f"--out: {str(args.out)!r} is a directory; give the .ssp file to write")
    if args.out.exists() and not args.force:
        raise ModelError(f"--out: {str(args.out)!r} exists; add --force to replace it or choose another file")
    if args.fmi_version == 3 and args.fmu_dir is not None:
        raise ModelError("--fmu-dir: not with --fmi-version 3, whose FMUs are built for the package")

    def say(line: str) -> None:
        print(f"sblsim: {line}", file=sys.stderr, flush=True)

    path = export_ssp(cfg, args.out, args.fmu_dir, fmi_version=args.fmi_version, report=say)
    print(f"wrote {path} ({cfg['run']['scenario']}, seed {cfg['run']['seed']}, receiver "
          f"{cfg['simulation']['receiver']}, FMI {args.fmi_version}.0); it validates against the SSP 1.0 schemas")
    return 0
