"""The C compiler: the system's when there is one, else zig from the ``ziglang`` package.

Every build uses the same flags, which keep the arithmetic IEEE-exact and
identical between the FMUs and the local engine: ``-O3`` without
``-ffast-math``, and ``-ffp-contract=off`` so that no compiler fuses a
multiply and an add (``fma``) on one platform and not on another. zig also
cross-compiles the FMU binaries for Windows and macOS.

Each C file is compiled once into an object file kept in the cache
(:func:`cache_dir`), keyed by everything its compilation reads: the compiler
and its version, the flags, the target, the file, the local headers it
includes and the macros it names. A library is then linked from them, so the
generated code of a model, compiled for the local engine's library, for its
FMU, for the FMU of a scenario (which differs only in its compiled-in start
values) or by ``sblsim fmus build`` again, is compiled once. A library's
objects compile side by side on every core, and processes that need the same
objects at once share the work (a lock file per object). Ctrl-C (or SIGTERM)
during a compilation ends it at once: the compilers running are stopped,
their partial files removed and nothing is kept half-written.
"""

from __future__ import annotations

import hashlib
import os
import platform
import re
import shlex
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Sequence

import platformdirs
from filelock import FileLock, Timeout

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
_INCLUDE = re.compile(rb'^\s*#\s*include\s*"([^"]+)"', re.M)


def cache_dir() -> Path:
    """Where compiled objects and libraries are kept: ``$SBLSIM_CACHE_DIR`` or the user's cache folder."""
    if os.environ.get("SBLSIM_CACHE_DIR"):
        return Path(os.environ["SBLSIM_CACHE_DIR"])
    return Path(platformdirs.user_cache_dir("sblsim"))


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
            command = [*compiler.command, *options]
            objects = _objects(compiler, command, sources, include, defines, target, folder)
            built.append(_run(compiler, [*command, *FLAGS, *map(str, objects), "-o", str(folder / output.name),
                                         *([] if target.startswith("win") else ["-lm"])],
                              folder / output.name, target))
        if len(built) > 1:
            universal_macho(built, Path(tmp) / output.name)
            built = [Path(tmp) / output.name]
        shutil.move(str(built[0]), str(output))
    return output


@lru_cache(maxsize=None)
def _identity(compiler: Compiler) -> bytes:
    """The compiler's command and the version it reports (another compiler or version: other objects)."""
    try:
        version = subprocess.run([*compiler.command, "--version"], capture_output=True, timeout=120).stdout
    except (OSError, subprocess.SubprocessError):
        version = b""
    return repr(compiler.command).encode() + b"\0" + version


def _headers(text: bytes, include: Sequence[Path], seen: dict[str, bytes]) -> None:
    """The local headers (``#include "..."`` found in ``include``) a text includes, transitively, into ``seen``."""
    for name in _INCLUDE.findall(text):
        name = name.decode()
        if name in seen:
            continue
        for folder in include:
            path = Path(folder) / name
            if path.is_file():
                seen[name] = path.read_bytes()
                _headers(seen[name], include, seen)
                break
        else:
            seen[name] = b""


@dataclass(frozen=True)
class _Object:
    """One C file's object: where it is kept, and the compiler command that makes it (but its output)."""

    source: Path
    path: Path
    command: tuple[str, ...]
    target: str
    compiler: Compiler


def _plan_object(compiler: Compiler, command: list[str], source: Path, include: Sequence[Path],
                 defines: Sequence[str], target: str, folder: Path) -> _Object:
    """``source``'s object in ``folder``, named by a key of everything its compilation reads: the compiler's
    identity, the command's options and the flags, the target, the file's name and bytes, the bytes of the local
    headers it includes and the macros whose names its text (or those headers') holds."""
    text = source.read_bytes()
    headers: dict[str, bytes] = {}
    _headers(text, include, headers)
    everything = b"\0".join([text, *headers.values()])
    used = [d for d in defines if re.search(rb"\b" + re.escape(d.split("=", 1)[0].encode()) + rb"\b", everything)]
    digest = hashlib.sha256(_identity(compiler) + repr((command[len(compiler.command):], FLAGS, target, used,
                                                        source.name)).encode())
    for name in sorted(headers):
        digest.update(name.encode() + b"\0" + headers[name] + b"\0")
    digest.update(text)
    return _Object(source, folder / f"{digest.hexdigest()[:40]}.o",
                   (*command, *FLAGS, *(f"-I{p}" for p in include), *(f"-D{d}" for d in used), "-c", str(source),
                    "-o"), target, compiler)


def _make(item: _Object, wait: bool, locked: bool = True, stop: threading.Event | None = None) -> bool:
    """Make ``item``'s object unless it is there; with ``locked``, under its lock file, which another process may
    hold (then, without ``wait``, leave it to that process: False). A set ``stop`` ends the wait or the
    compilation (:class:`_Stopped`)."""
    if item.path.is_file():
        return True
    lock = FileLock(str(item.path) + ".lock") if locked else None
    while lock is not None:  # another process may compile it: wait a fraction of a second at a time
        try:
            lock.acquire(timeout=_POLL if wait else 0)
            break
        except Timeout:
            if not wait:
                return False
            if stop is not None and stop.is_set():
                raise _Stopped from None
    try:
        if not item.path.is_file():
            partial = item.path.with_name(f".{item.path.name}.{os.getpid()}.{threading.get_ident()}.partial")
            try:
                _run(item.compiler, [*item.command, str(partial)], partial, item.target, item.source.name, stop)
                os.replace(partial, item.path)
            finally:
                partial.unlink(missing_ok=True)
    finally:
        if lock is not None:
            lock.release()
    return True


def _objects(compiler: Compiler, command: list[str], sources: Sequence[Path], include: Sequence[Path],
             defines: Sequence[str], target: str, work: Path) -> list[Path]:
    """The sources' objects: from the cache, else compiled (several at once, on every core) and kept.

    Processes that need the same objects at once share the work: each first compiles those no other is
    compiling, then waits for the rest. A cache that cannot be written only costs the compilations (into
    ``work``)."""
    folder = cache_dir() / "objects"
    try:  # a cache this process can write into (checked by writing)
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
        locked = True
    except OSError:
        folder, locked = work, False
    items = [_plan_object(compiler, command, Path(source), include, defines, target, folder) for source in sources]
    stop = threading.Event()
    pool = ThreadPoolExecutor(max_workers=max(1, min(len(items), os.cpu_count() or 1)))
    try:
        done = list(pool.map(lambda item: _make(item, False, locked, stop), items))
        list(pool.map(lambda item: _make(item, True, locked, stop), [i for i, ok in zip(items, done) if not ok]))
    except BaseException:  # Ctrl-C, SIGTERM or a compiler's error: the other compilations stop too
        stop.set()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return [item.path for item in items]


class _Stopped(Exception):
    """A compilation ended because another one failed or the user interrupted the build."""


#: How often [s] a compilation or a wait in a worker thread looks whether it should stop.
_POLL = 0.1


def _run(compiler: Compiler, command: list[str], built: Path, target: str, what: str = "",
         stop: threading.Event | None = None) -> Path:
    """One compiler run that writes ``built`` (of ``what``, default its name); raises CompileError with the
    compiler's first error lines.

    The compiler runs in a process group of its own (on POSIX), so a terminal's Ctrl-C reaches this process
    only; an exception here (KeyboardInterrupt in the main thread) or a set ``stop`` (a worker thread) kills
    the group — the compiler and what it started (zig's wrapper starts zig) — before anything is returned. Its
    temporary files (``TMPDIR``, ``TMP``, ``TEMP``) go to a folder of its own, removed after it even when killed."""
    posix = os.name == "posix"
    # the compiler's own temporary files (gcc's assembly, a killed compiler's leftovers) in a folder removed after it
    with tempfile.TemporaryDirectory(prefix="sblsim_cc_") as scratch:
        env = {**os.environ, "TMPDIR": scratch, "TMP": scratch, "TEMP": scratch}
        proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                cwd=built.parent, start_new_session=posix, env=env)
        try:
            while True:
                try:
                    stdout, stderr = proc.communicate(timeout=None if stop is None else _POLL)
                    break
                except subprocess.TimeoutExpired:
                    if stop is not None and stop.is_set():
                        raise _Stopped from None
        except BaseException:
            try:
                os.killpg(proc.pid, signal.SIGKILL) if posix else proc.kill()
            except ProcessLookupError:
                pass
            proc.communicate()
            raise
    if proc.returncode != 0 or not built.is_file():
        errors = [line for line in (stderr or stdout).splitlines() if "error" in line.lower()]
        detail = " | ".join((errors or (stderr or stdout).splitlines())[:3])
        raise CompileError(f"compiler: {compiler.describe()} failed for {what or built.name} ({target}): {detail}")
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

__all__ = ["COMPILERS", "CROSS_PLATFORMS", "CompileError", "Compiler", "FLAGS", "PLATFORMS", "cache_dir",
           "compile_library",
           "find_compiler", "host_platform", "universal_macho", "zig"]
