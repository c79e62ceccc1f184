"""``sblsim codegen receiver``: a receiver's embeddable C source, header and example ``main.c`` (no FMI, no
Python; :mod:`sblsim.fmus.embedded`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from sblsim.fmus.embedded import write_receiver
from sblsim.models import RECEIVERS
from sblsim.models.declarations import ModelError
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.io.output import check_writable

NAME = "codegen"
HELP = "write embeddable C code of a component (no FMI, no Python)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim codegen``'s arguments."""
    gsub = p.add_subparsers(dest="codegen_command", required=True, parser_class=type(p))
    r = gsub.add_parser("receiver", help="the receiver's C source, header and an example main.c")
    r.add_argument("--receiver", default="ekf", help="built-in receiver: ekf (default), ekf-seq, ukf or lsq")
    r.add_argument("--system", default=next(iter(SYSTEMS)), choices=tuple(SYSTEMS),
                   help=f"the positioning system whose packets the receiver takes (default {next(iter(SYSTEMS))}): "
                        + "; ".join(f"{s.name}: {s.title}" for s in SYSTEMS.values()))
    r.add_argument("--out", type=Path, required=True, help="directory to write (created; must be empty or new)")


def main(args: argparse.Namespace) -> int:
    """``sblsim codegen`` from its parsed arguments: its lines printed, its exit status returned."""
    from sblsim.orchestrator.cosim.codegen import example_files

    check_writable(args.out)
    if args.receiver not in RECEIVERS:
        raise ModelError(f"--receiver: {args.receiver!r} is not one of {', '.join(RECEIVERS)}")
    example, about, n_beacons = example_files(args.receiver, args.system)
    files = write_receiver(args.receiver, args.out, n_beacons, example=example, about=about)
    print(f"wrote {len(files)} files to {args.out}/ ({', '.join(p.name for p in files)}); see its README.md")
    return 0
