"""``sblsim fmus build|validate|variables``: the FMI 2.0 Co-Simulation FMUs built from the model source
(:mod:`sblsim.fmus.build`), a scenario's FMUs whose start values are its parameters
(:mod:`sblsim.orchestrator.cosim.scenario_fmus`), fmpy's validation, the variables as Markdown tables.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable

from sblsim.fmus.build import DEFAULT_DIR, FMI_VERSIONS, beacons_dir, build_fmu, fmu_path, validate, version_dir
from sblsim.fmus.compiler import COMPILERS
from sblsim.fmus.variables import markdown_tables
from sblsim.models import MODELS
from sblsim.models.declarations import ModelError
from sblsim.models.platform.core import MAX_BEACONS, MIN_BEACONS
from sblsim.models.systems import SYSTEMS, interface_owners
from sblsim.orchestrator.commands.common import resolve_plan
from sblsim.orchestrator.commands.console import check_seed_option
from sblsim.orchestrator.cosim.config import MODEL_PREFIX, check_receiver, external_path
from sblsim.orchestrator.cosim.plugins import user_model
from sblsim.orchestrator.cosim.scenario_fmus import build_scenario_fmus
from sblsim.orchestrator.io.output import check_writable

#: The systems that own components' interfaces (``fmus build --system``): the layout-sized one first.
_OWNERS = tuple(s.name for s in interface_owners())
_FIXED = ", ".join(name for name in _OWNERS if SYSTEMS[name].interface_beacons is not None)


NAME = "fmus"
HELP = "build, validate or list the FMI 2.0 (and 3.0) Co-Simulation FMUs"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim fmus``'s arguments."""
    fsub = p.add_subparsers(dest="fmus_command", required=True, parser_class=type(p))
    b = fsub.add_parser("build", help="build the native FMUs (four components and the alternative receivers)")
    b.add_argument("--out", type=Path, default=None, help=f"output directory (default {DEFAULT_DIR})")
    b.add_argument("--fmi-version", type=int, choices=FMI_VERSIONS, default=2,
                   help="2 (default) or 3: FMI 3.0 Co-Simulation FMUs from the same C, with arrays, into the "
                        "folder fmi3 of the output (docs/interop.md, FMI 3.0)")
    b.add_argument("--compiler", choices=COMPILERS, default="auto",
                   help="C compiler: auto (the system's, else zig), system or zig")
    b.add_argument("--cross", action=argparse.BooleanOptionalAction, default=None,
                   help="also build Windows and macOS binaries with zig (default: when the compiler is zig)")
    b.add_argument("--model", type=Path, default=None, metavar="PATH.py",
                   help="build only the receiver model this Python file defines (see docs/extending.md, "
                        "Write your own receiver)")
    b.add_argument("--beacons", type=int, default=4, metavar="N",
                   help="beacons of the interfaces (default 4; other N go to the folder beacons<N> of the output)")
    b.add_argument("--system", choices=_OWNERS, default=_OWNERS[0],
                   help=f"{_FIXED}: the interfaces of that system (its folder of the output); the others use the "
                        f"{_OWNERS[0]} interfaces of --beacons N (default {_OWNERS[0]})")
    b.add_argument("--scenario", default=None, metavar="NAME|CONFIG.toml",
                   help="build that scenario's FMUs (the set `sblsim ssp export` packs, into --out, which is "
                        "required) with its parameters as their start values and compiled-in defaults: a host that "
                        "sets nothing runs the scenario (docs/interop.md)")
    b.add_argument("--seed", type=int, default=None, help="with --scenario: the campaign seed (default: the "
                   "configuration's, 0)")
    b.add_argument("--receiver", default=None,
                   help="with --scenario: ekf, ekf-seq, ukf, lsq or model:PATH.py (default: the scenario's)")
    b.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="with --scenario: override a configuration key (repeatable)")
    fsub.add_parser("variables", help="print every FMU's variables as Markdown tables (from the declarations)")
    v = fsub.add_parser("validate", help="validate the FMUs with fmpy")
    v.add_argument("dir", type=Path, nargs="?", default=None, help=f"directory of the FMUs (default {DEFAULT_DIR})")
    v.add_argument("--beacons", type=int, default=4, metavar="N",
                   help="validate the FMUs built for N beacons (default 4: the folder beacons<N> for others)")
    v.add_argument("--fmi-version", type=int, choices=FMI_VERSIONS, default=2,
                   help="validate the FMI 3.0 FMUs (the folder fmi3) with 3 (default 2)")
    v.add_argument("--system", choices=_OWNERS, default=_OWNERS[0],
                   help=f"{_FIXED}: validate that system's interfaces' FMUs (its folder)")


def main(args: argparse.Namespace) -> int:
    """``sblsim fmus`` from its parsed arguments: its lines printed, its exit status returned."""
    n_beacons = getattr(args, "beacons", 4)
    if not MIN_BEACONS <= n_beacons <= MAX_BEACONS:
        raise ModelError(f"--beacons: {n_beacons} is outside the allowed range [{MIN_BEACONS}, {MAX_BEACONS}]")
    system = SYSTEMS[getattr(args, "system", _OWNERS[0])]
    if system.interface_beacons is not None:  # a system of a fixed interface (USBL's one transceiver)
        if n_beacons != 4:
            raise ModelError(f"--beacons: {n_beacons} with --system {system.name}, whose interface has "
                             f"{system.interface_beacons}")
        n_beacons = system.interface_beacons
    if args.fmus_command == "variables":
        print(markdown_tables())
        return 0
    if args.fmus_command == "build":
        def say(line: str) -> None:  # each target's binary takes seconds (cross: a minute): progress lines
            print(f"sblsim: {line}", file=sys.stderr, flush=True)

        if args.scenario is not None:
            return _scenario_fmus(args, say)
        for option, given in (("--seed", args.seed is not None), ("--receiver", args.receiver is not None),
                              ("--set", bool(args.overrides))):
            if given:
                raise ModelError(f"{option}: only with --scenario NAME|CONFIG.toml (the scenario's FMUs)")
        out = version_dir(beacons_dir(args.out or DEFAULT_DIR, n_beacons), args.fmi_version)
        check_writable(out)
        options = dict(compiler=args.compiler, cross=args.cross, report=say, fmi_version=args.fmi_version)
        if args.model is not None:
            check_receiver(f"{MODEL_PREFIX}{args.model}", "--model")
            model = user_model(args.model)
            print(f"built {build_fmu(model, out, n_beacons, **options)}", flush=True)
            return 0
        for name in MODELS:
            print(f"built {build_fmu(name, out, n_beacons, **options)}", flush=True)
        return 0
    directory = version_dir(beacons_dir(args.dir or DEFAULT_DIR, n_beacons), args.fmi_version)
    failures = 0
    for name in MODELS:
        path = fmu_path(directory, name)
        if not path.is_file():
            raise ModelError(f"fmus validate: {name} FMU not found at {str(path)!r}; run `sblsim fmus build"
                             f"{' --fmi-version 3' if args.fmi_version == 3 else ''}`")
        problems = validate(path)
        failures += bool(problems)
        print(f"{path}: {len(problems)} problems")
        for problem in problems:
            print(f"  {problem}")
    return 1 if failures else 0


def _scenario_fmus(args: argparse.Namespace, say: Callable[[str], None]) -> int:
    """``sblsim fmus build --scenario``: the scenario's FMUs, its parameters as their defaults."""
    for option, given in (("--model", args.model is not None), ("--beacons", args.beacons != 4),
                          ("--system", args.system != _OWNERS[0])):
        if given:
            raise ModelError(f"{option}: not with --scenario, whose configuration sets the system, beacons and "
                             "receiver (--receiver NAME)")
    if args.out is None:
        raise ModelError("--out: give the folder for the scenario's FMUs (--scenario needs --out DIR)")
    check_seed_option(args.seed)
    overrides = list(args.overrides)
    if args.receiver is not None:
        check_receiver(args.receiver, "--receiver")
        if external_path(args.receiver):
            raise ModelError(f"--receiver: {args.receiver!r} is an FMU; a scenario is built into the FMUs sblsim "
                             "generates: ekf, ekf-seq, ukf, lsq or model:PATH.py")
        overrides.append(f"receiver={args.receiver}")
    plan = resolve_plan(args.scenario, args.seed, overrides)
    check_writable(args.out)
    for path in build_scenario_fmus(plan, args.out, args.compiler, args.cross, report=say,
                                    fmi_version=args.fmi_version):
        print(f"built {path}", flush=True)
    print(f"the FMUs' start values are {plan.scenario}'s (seed {plan.seed}, receiver {plan.receiver}); a host "
          f"that sets nothing runs it for {plan.duration:g} s in steps of "
          f"{plan.sampling_time / plan.ekf_rate_ratio:g} s")
    return 0
