"""The C compiler: the system's when there is one, else zig from the ``ziglang`` package.

Every build uses the same flags, which keep the arithmetic IEEE-exact and
identical between the FMUs and the local engine: ``-O2`` without
``-ffast-math``, and ``-ffp-contract=off`` so that no compiler fuses a
multiply and an add (``fma``) on one platform and not on another. zig also
cross-compiles the FMU binaries for Windows and macOS.
"""

from __future__ import annotations

import os
import platform
import shlex
import shutil
import struct
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from sblsim.models.errors import CompileError

FLAGS = ("-O3", "-std=c99", "-ffp-contract=off", "-fno-math-errno", "-fvisibility=hidden", "-fPIC", "-shared")

#: FMI 2.0 platform folder -> (zig targets, library suffix). FMI 2.0 knows one macOS folder, ``darwin64``, and
#: its hosts (fmpy, OMSimulator) read it on Intel and Apple silicon alike, so its library is a universal Mach-O
#: file holding both slices (as ``lipo`` makes it: :func:`universal_macho`).
PLATFORMS = {
    "linux64": (("x86_64-linux-gnu",), ".so"),
    "win64": (("x86_64-windows-gnu",), ".dll"),
    "darwin64": (("x86_64-macos", "aarch64-macos"), ".dylib"),
}
CROSS_PLATFORMS = ("win64", "darwin64")
#: Mach-O CPU types of the zig targets' architectures, and the alignment (log2) of their slices.
_MACHO_CPU = {"x86_64": (0x01000007, 3, 12), "aarch64": (0x0100000C, 0, 14)}
COMPILERS = ("auto", "system", "zig")


@dataclass(frozen=True)
class Compiler:
    """A C compiler command.

    Attributes
    ----------
    command : tuple of str
        The command (``('cc',)`` or ``(python, '-m', 'ziglang', 'cc')``).
    zig : bool
        It is zig (it can cross-compile).
    """

    command: tuple[str, ...]
    zig: bool

    def describe(self) -> str:
        return "zig (ziglang package)" if self.zig else " ".join(self.command)


def zig() -> Compiler | None:
    """zig from the ``ziglang`` package, if installed."""
    try:
        import ziglang  # noqa: F401
    except ImportError:
        return None
    return Compiler((sys.executable, "-m", "ziglang", "cc"), True)


def find_compiler(kind: str = "auto") -> Compiler:
    """The compiler to use.

    Parameters
    ----------
    kind : {'auto', 'system', 'zig'}
        ``auto``: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH, else zig;
        ``system``: one of those only; ``zig``: zig only.

    Raises
    ------
    CompileError
        If no such compiler is found.
    """
    if kind not in COMPILERS:
        raise CompileError(f"--compiler: {kind!r} is not one of {', '.join(COMPILERS)}")
    if kind in ("auto", "system"):
        if os.environ.get("CC"):
            return Compiler(tuple(shlex.split(os.environ["CC"])), False)
        for name in ("cc", "gcc", "clang"):
            if shutil.which(name):
                return Compiler((name,), False)
        if kind == "system":
            raise CompileError("--compiler: no system C compiler (cc, gcc, clang or $CC) on the PATH")
    found = zig()
    if found is None:
        raise CompileError("compiler: no C compiler found; install one (e.g. gcc) or `pip install ziglang`")
    return found


def host_platform() -> str:
    """FMI 2.0 platform folder of this machine.

    Raises
    ------
    CompileError
        On a platform sblsim does not build for.
    """
    machine = platform.machine().lower()
    if sys.platform.startswith("linux") and machine in ("x86_64", "amd64"):
        return "linux64"
    if sys.platform == "win32" and machine in ("x86_64", "amd64"):
        return "win64"
    if sys.platform == "darwin" and machine in ("x86_64", "amd64", "arm64", "aarch64"):
        return "darwin64"
    raise CompileError(f"compiler: no FMI 2.0 platform folder for {sys.platform}/{machine}")


def compile_library(compiler: Compiler, sources: Sequence[Path], output: Path, include: Sequence[Path] = (),
                    defines: Sequence[str] = (), platform: str | None = None) -> Path:
    """Compile C sources into a shared library.

    Parameters
    ----------
    compiler : Compiler
    sources : sequence of path
    output : path
        The library to write.
    include : sequence of path
        Include directories.
    defines : sequence of str
        ``NAME=VALUE`` macros.
    platform : str, optional
        FMI platform folder to build for (default: this machine); other
        platforms need zig.

    Raises
    ------
    CompileError
        If the compiler fails (the message carries its first error lines).
    """
    target = platform or host_platform()
    if target != host_platform() and not compiler.zig:
        raise CompileError(f"compiler: cross-compiling for {target} needs zig (`pip install ziglang`)")
    if compiler.zig:  # one compilation per slice
        slices = [["-target", zig_target] for zig_target in PLATFORMS[target][0]]
    else:  # the host's own compiler; Apple's makes a universal library itself
        slices = [["-arch", "x86_64", "-arch", "arm64"] if target == "darwin64" else []]
    with tempfile.TemporaryDirectory(prefix="sblsim_cc_") as tmp:
        built = []
        for k, options in enumerate(slices):
            # in a folder of its own: some linkers leave companions (a .pdb, an import .lib) beside the library
            folder = Path(tmp) / str(k)
            folder.mkdir()
            built.append(_compile(compiler, [*compiler.command, *options], sources, folder / output.name, include,
                                  defines, target))
        if len(built) > 1:
            universal_macho(built, Path(tmp) / output.name)
            built = [Path(tmp) / output.name]
        shutil.move(str(built[0]), str(output))
    return output


def _compile(compiler: Compiler, command: list[str], sources: Sequence[Path], built: Path, include: Sequence[Path],
             defines: Sequence[str], target: str) -> Path:
    """One compiler run into ``built``; raises CompileError with the compiler's first error lines."""
    command = [*command, *FLAGS, *(f"-I{p}" for p in include), *(f"-D{d}" for d in defines),
               *(str(s) for s in sources), "-o", str(built)]
    if not target.startswith("win"):
        command.append("-lm")
    result = subprocess.run(command, capture_output=True, text=True, cwd=built.parent)
    if result.returncode != 0 or not built.is_file():
        errors = [line for line in (result.stderr or result.stdout).splitlines() if "error" in line.lower()]
        detail = " | ".join((errors or (result.stderr or result.stdout).splitlines())[:3])
        raise CompileError(f"compiler: {compiler.describe()} failed for {built.name} ({target}): {detail}")
    return built


def universal_macho(slices: Sequence[Path], output: Path) -> Path:
    """Join thin Mach-O libraries into one universal ("fat") file, as Apple's ``lipo -create`` does.

    The file is a big-endian header (magic ``0xCAFEBABE``, the number of slices), one record per slice
    (CPU type, CPU subtype, offset, size, alignment as a power of 2), then the slices, each at an offset
    aligned to its page size (Apple, ``<mach-o/fat.h>``).

    Raises
    ------
    CompileError
        If a slice is not a 64-bit little-endian Mach-O file of a known architecture.
    """
    cpus = {cpu: (cpu, sub, align) for cpu, sub, align in _MACHO_CPU.values()}
    blobs, records = [p.read_bytes() for p in slices], []
    offset = 8 + 20 * len(blobs)
    for path, blob in zip(slices, blobs):
        magic, cpu = struct.unpack_from("<II", blob, 0)
        if magic != 0xFEEDFACF or cpu not in cpus:
            raise CompileError(f"compiler: {path.name} is not a 64-bit Mach-O library of x86_64 or arm64")
        _, sub, align = cpus[cpu]
        offset = -(-offset // (1 << align)) * (1 << align)
        records.append((cpu, sub, offset, len(blob), align))
        offset += len(blob)
    with open(output, "wb") as out:
        out.write(struct.pack(">II", 0xCAFEBABE, len(blobs)))
        for record in records:
            out.write(struct.pack(">IIIII", *record))
        for (_, _, at, _, _), blob in zip(records, blobs):
            out.write(bytes(at - out.tell()))
            out.write(blob)
    return output

__all__ = ["COMPILERS", "CROSS_PLATFORMS", "CompileError", "Compiler", "FLAGS", "PLATFORMS", "compile_library",
           "find_compiler", "host_platform", "universal_macho", "zig"]
