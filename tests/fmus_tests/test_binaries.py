"""The FMU binaries where FMI users live: a plain C host, valgrind, their dynamic dependencies,
an independent FMU checker, other platforms, another compiler, and the random streams in C."""

from __future__ import annotations

import math
import shutil
import struct
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from sblsim.fmus.build import build_fmu, fmu_path
from sblsim.fmus.compiler import find_compiler
from sblsim.fmus.native import stream
from sblsim.models import MODELS, RECEIVERS
from sblsim.models.philox import normals, uniforms
from tests.fmus_tests.test_fmi_semantics import finite_but_the_estimate_before_a_fix

NAMES = list(MODELS)


def unpack(fmu: Path, into: Path) -> tuple[Path, str, list[int]]:
    """Extract an FMU; its linux64 binary, GUID and the value references of its Real outputs."""
    with zipfile.ZipFile(fmu) as archive:
        archive.extractall(into)
    md = read_model_description(str(fmu))
    outputs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    return into / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so", md.guid, outputs


#: A Real parameter per FMU that changes its outputs even with all inputs at zero, and a value for it. A Kalman
#: receiver without a packet has no estimate (NaN, never its starting guess x0_*) but its covariance grows from
#: p0_position; lsq without a packet outputs nothing any parameter changes (no fix, no covariance): its x0_x must
#: leave every output as it is.
CHANGED = {"platform": ("baseline", 2.5), "acoustics": ("sigma_range", 0.7), "target": ("radius", 12.0),
           **{name: ("p0_position", 3.0) for name in RECEIVERS.values() if name != "receiver_lsq"},
           "receiver_lsq": ("x0_x", 3.0)}


def first_real_parameter(name: str) -> tuple[int, float]:
    """Value reference and value of the parameter :data:`CHANGED` sets for an FMU."""
    parameter, value = CHANGED[name]
    return [v.name for v in MODELS[name].fmu_variables()].index(parameter), value


def run_host(c_host: Path, binary: Path, guid: str, uri: str, outputs: list[int], params: str,
             wrapper: list[str] = ()) -> subprocess.CompletedProcess:
    return subprocess.run([*wrapper, str(c_host), str(binary), guid, uri, "30", "0.1", params],
                          input="\n".join(map(str, outputs)), capture_output=True, text=True, env={}, timeout=300)


def parse(stdout: str) -> dict[str, np.ndarray]:
    rows = {"a": [], "b": []}
    for line in stdout.splitlines():
        parts = line.split()
        rows[parts[0]].append([float(x) for x in parts[2:]])
    return {k: np.array(v) for k, v in rows.items()}


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_plain_c_host_with_an_empty_environment_two_instances_and_both_uri_forms(fmu_dir, c_host, tmp_path, name):
    binary, guid, outputs = unpack(fmu_path(fmu_dir, name), tmp_path)
    vr, value = first_real_parameter(name)
    results = []
    for uri in (f"file:{tmp_path}/resources", f"file://{tmp_path}/resources"):
        proc = run_host(c_host, binary, guid, uri, outputs, f"{vr}={value!r}")
        assert proc.returncode == 0, proc.stderr[-2000:]
        results.append(parse(proc.stdout))
    a, b = results[0]["a"], results[0]["b"]
    names = [v.name for v in read_model_description(str(fmu_path(fmu_dir, name))).modelVariables
             if v.causality == "output" and v.type == "Real"]
    assert a.shape == b.shape == (30, len(outputs))
    # every output finite but a receiver's estimate, which without a packet is never defined (NaN, printed by
    # the host as nan or -nan)
    for rows in (a, b):
        estimated = finite_but_the_estimate_before_a_fix(names, rows)
        assert not (name.startswith("receiver") and estimated.any())
    np.testing.assert_array_equal(results[1]["a"], a)  # the URI form changes nothing
    if name == "receiver_lsq":  # its starting guess is not an output: b's x0_x changes nothing without a fix
        np.testing.assert_array_equal(b, a)
    else:
        assert not np.array_equal(a, b, equal_nan=True)  # instance b carries its own parameter value
    # instance a equals a run of the same FMU through fmpy (another host, another process state); the two hosts
    # compute the communication points differently (k h against t + h), hence round-off in the time
    from fmpy import simulate_fmu

    ref = simulate_fmu(str(fmu_path(fmu_dir, name)), stop_time=3.0, output_interval=0.1)
    np.testing.assert_allclose(np.column_stack([ref[n][1:] for n in names]), a, rtol=0, atol=1e-12)


@pytest.mark.slow
def test_a_wrong_guid_is_refused_with_a_log_line(fmu_dir, c_host, tmp_path):
    binary, guid, outputs = unpack(fmu_path(fmu_dir, "target"), tmp_path)
    proc = run_host(c_host, binary, "{not-the-guid}", f"file://{tmp_path}", outputs, "")
    assert proc.returncode == 3 and "does not match" in proc.stderr and "NULL" in proc.stderr


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind is not installed")
@pytest.mark.parametrize("name", NAMES)
def test_memcheck_finds_no_error_and_no_leak(fmu_dir, c_host, tmp_path, name):
    binary, guid, outputs = unpack(fmu_path(fmu_dir, name), tmp_path)
    vr, value = first_real_parameter(name)
    proc = run_host(c_host, binary, guid, f"file://{tmp_path}", outputs, f"{vr}={value!r}",
                    wrapper=[shutil.which("valgrind"), "--error-exitcode=9", "--leak-check=full",
                             "--errors-for-leak-kinds=definite"])
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "ERROR SUMMARY: 0 errors" in proc.stderr
    assert "definitely lost" not in proc.stderr or "definitely lost: 0 bytes" in proc.stderr


@pytest.mark.parametrize("name", NAMES)
def test_the_binary_needs_only_the_c_library(fmu_dir, tmp_path, name):
    """The ELF dynamic section lists libc and libm only: no libpython, nothing else to install."""
    from elftools.elf.dynamic import DynamicSection
    from elftools.elf.elffile import ELFFile

    binary, _, _ = unpack(fmu_path(fmu_dir, name), tmp_path)
    with open(binary, "rb") as handle:
        elf = ELFFile(handle)
        needed = [tag.needed for section in elf.iter_sections() if isinstance(section, DynamicSection)
                  for tag in section.iter_tags() if tag.entry.d_tag == "DT_NEEDED"]
        exported = {s.name for s in elf.get_section_by_name(".dynsym").iter_symbols()
                    if s.entry.st_info.bind == "STB_GLOBAL" and s.entry.st_shndx != "SHN_UNDEF"}
    assert needed and all(n.split(".so")[0] in ("libc", "libm") for n in needed), needed
    assert not any("python" in n for n in needed)
    assert {"fmi2Instantiate", "fmi2DoStep", "fmi2GetFMUstate"} <= exported
    assert not any(s.startswith(("sblsim_", "casadi_")) for s in exported)  # nothing else leaks out


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_fmu_manipulation_toolbox_checker_reports_compliance(fmu_dir, name):
    from fmu_manipulation_toolbox.checker import get_checkers
    from fmu_manipulation_toolbox.operations import FMU

    with FMU(str(fmu_path(fmu_dir, name))) as fmu:
        checkers = [c() for c in get_checkers()]
        for checker in checkers:
            fmu.apply_operation(checker)
    generic = next(c for c in checkers if hasattr(c, "compliant_with_version"))
    assert generic.compliant_with_version == "2.0"
    assert all(not getattr(c, "errors", 0) for c in checkers)


# --------------------------------------------------------------------------- other platforms and compilers

def binary_format(path: Path) -> tuple[str, str]:
    """(format, machine) read from a binary's header: ELF, PE or Mach-O."""
    data = path.read_bytes()[:4096]
    if data[:4] == b"\x7fELF":
        return "ELF", {62: "x86_64", 183: "aarch64"}[struct.unpack_from("<H", data, 18)[0]]
    if data[:2] == b"MZ":
        offset = struct.unpack_from("<I", data, 0x3C)[0]
        assert data[offset:offset + 4] == b"PE\0\0"
        return "PE", {0x8664: "x86_64", 0xAA64: "aarch64"}[struct.unpack_from("<H", data, offset + 4)[0]]
    if struct.unpack_from("<I", data, 0)[0] == 0xFEEDFACF:
        cpu = struct.unpack_from("<I", data, 4)[0]
        return "Mach-O", {0x01000007: "x86_64", 0x0100000C: "aarch64"}[cpu]
    raise AssertionError(f"{path.name}: unknown binary format")


@pytest.mark.slow
def test_zig_cross_compiles_windows_and_macos_binaries(tmp_path):
    """With zig (the ziglang package) an FMU also carries win64 and darwin64 binaries; darwin64, the one macOS
    folder of FMI 2.0, is a universal library with an x86_64 and an arm64 slice (read by macholib)."""
    from fmpy import supported_platforms
    from macholib.MachO import MachO

    fmu = build_fmu("target", tmp_path, cross=True)
    with zipfile.ZipFile(fmu) as archive:
        archive.extractall(tmp_path / "x")
    binaries = tmp_path / "x" / "binaries"
    expected = {"linux64/sblsim_target.so": ("ELF", "x86_64"), "win64/sblsim_target.dll": ("PE", "x86_64")}
    for relative, (fmt, machine) in expected.items():
        assert binary_format(binaries / relative) == (fmt, machine), relative
    universal = binaries / "darwin64" / "sblsim_target.dylib"
    assert struct.unpack_from(">I", universal.read_bytes(), 0)[0] == 0xCAFEBABE
    slices = MachO(str(universal)).headers
    assert sorted(h.header.cputype & 0xFFFFFF for h in slices) == [7, 12]  # x86_64, arm64
    for h in slices:  # each slice is a whole library: its load commands parse and it exports the FMI calls
        assert h.header.filetype == 6 and len(h.commands) == h.header.ncmds  # MH_DYLIB
    assert b"_fmi2DoStep" in universal.read_bytes()
    found = {p.relative_to(binaries).as_posix() for p in binaries.rglob("*") if p.is_file()}
    assert found == set(expected) | {"darwin64/sblsim_target.dylib"}  # no debug database, no import library
    assert {"linux64", "win64", "darwin64"} <= set(supported_platforms(str(fmu)))


@pytest.mark.slow
def test_zig_and_the_system_compiler_give_the_same_numbers(tmp_path):
    """A machine without a C compiler builds with zig; its FMU computes the same outputs to the bit."""
    from fmpy import simulate_fmu

    results = []
    for compiler in ("system", "zig"):
        fmu = build_fmu("acoustics", tmp_path / compiler, compiler=compiler, cross=False)
        results.append(simulate_fmu(str(fmu), stop_time=2.0, output_interval=0.1,
                                    start_values={"sigma_range": 0.5, "loss_pct": 30.0}))
    for column in results[0].dtype.names:
        np.testing.assert_array_equal(results[0][column], results[1][column])


@pytest.mark.slow
def test_the_fmu_rebuilds_from_its_own_sources(fmu_dir, c_host, tmp_path):
    """sources/ holds everything: compiling it gives a binary with the same outputs."""
    binary, guid, outputs = unpack(fmu_path(fmu_dir, "receiver_lsq"), tmp_path)
    rebuilt = tmp_path / "rebuilt.so"
    cc = find_compiler("system")
    sources = sorted((tmp_path / "sources").glob("*.c"))
    subprocess.run([*cc.command, "-shared", "-fPIC", "-O2", "-std=c99", "-ffp-contract=off",
                    "-DSBLSIM_MODEL=sblsim_receiver_lsq_model", f"-I{tmp_path / 'sources'}", *map(str, sources),
                    "-o", str(rebuilt), "-lm"], check=True, capture_output=True)
    vr, value = first_real_parameter("receiver_lsq")
    shipped = run_host(c_host, binary, guid, f"file://{tmp_path}", outputs, f"{vr}={value!r}")
    own = run_host(c_host, rebuilt, guid, f"file://{tmp_path}", outputs, f"{vr}={value!r}")
    assert shipped.returncode == own.returncode == 0
    assert shipped.stdout == own.stdout


# --------------------------------------------------------------------------- the random streams

@pytest.mark.parametrize("keys, component, purpose, draw", [
    ((0, 0, 0, 0), 0, 0, 0), ((1, 2, 3, 4), 1, 0, 5), ((2**31 - 1, 7, 127, 49), 3, 2, 123456),
])
def test_philox_streams_are_the_same_in_c_and_numpy(keys, component, purpose, draw):
    """The first numbers of a stream: the C runtime equals numpy's Philox bit generator (uniforms exactly;
    normals through the same Box-Muller with the C library's log, sqrt and cos), for counts of one block,
    several, and ending part-way through a block."""
    seed, scenario, cell, replicate = keys
    for count in (1, 9, 37):
        np.testing.assert_array_equal(stream("uniform", keys, component, purpose, draw, count),
                                      uniforms(seed, scenario, cell, replicate, component, purpose, draw, count))
    for count in (1, 5, 19):
        np.testing.assert_array_equal(stream("normal", keys, component, purpose, draw, count),
                                      normals(seed, scenario, cell, replicate, component, purpose, draw, count))


def test_philox_reference_is_numpys_bit_generator():
    """sblsim.models.philox.uniforms is numpy.random.Philox with the documented key and counter, and its
    streams are distinct: another purpose, draw, cell or replicate gives other numbers."""
    gen = np.random.Philox(key=np.array([5, (1 << 32) | (2 << 16) | 3], dtype=np.uint64),
                           counter=np.array([2**64 - 1, 6, 7, 8], dtype=np.uint64))  # = counter (0, 7, 7, 8) - 1
    words = gen.random_raw(4)
    np.testing.assert_array_equal(uniforms(5, 1, 7, 8, 2, 3, 7, 4), (words >> np.uint64(11)) * 2.0**-53)
    base = uniforms(5, 1, 7, 8, 2, 3, 7, 8)
    for other in (uniforms(5, 1, 7, 8, 2, 4, 7, 8), uniforms(5, 1, 7, 8, 2, 3, 8, 8),
                  uniforms(5, 1, 6, 8, 2, 3, 7, 8), uniforms(5, 1, 7, 9, 2, 3, 7, 8)):
        assert not np.any(other == base)
    big = uniforms(1, 0, 0, 0, 0, 0, 0, 40000)
    assert 0.0 <= big.min() and big.max() < 1.0 and abs(big.mean() - 0.5) < 0.01


def run_channel(c_host: Path, fmu_dir: Path, tmp_path: Path, values: dict, steps: int = 30) -> dict[str, np.ndarray]:
    """The channel FMU's instance b in the plain C host (no Python, an empty environment), ``values`` (parameters
    and inputs by name: Reals, Integers, String choices as text) set before initialization, ``steps`` steps of
    0.1 s: each Real output by name, one value per step."""
    binary, guid, outputs = unpack(fmu_path(fmu_dir, "acoustics"), tmp_path)
    declared = MODELS["acoustics"].fmu_variables()
    index = {v.name: k for k, v in enumerate(declared)}
    params = []
    for name, value in values.items():
        variable = declared[index[name]]
        if variable.type == "Real":
            params.append(f"{index[name]}={float(value)!r}")
        else:
            params.append(f"i{index[name]}={variable.choices.index(value) if variable.choices else int(value)}")
    proc = subprocess.run([str(c_host), str(binary), guid, f"file://{tmp_path}/resources", str(steps), "0.1",
                           *params], input="\n".join(map(str, outputs)), capture_output=True, text=True, env={},
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = parse(proc.stdout)["b"]
    return {declared[vr].name: rows[:, k] for k, vr in enumerate(outputs)}


#: A sound-speed table of the channel tests in the C host: refracting, and a minimum at 200 m [m, m/s].
TABLE = np.array([[0.0, 1500.0], [50.0, 1490.0], [200.0, 1470.0], [500.0, 1485.0], [1000.0, 1500.0]])


@pytest.mark.slow
def test_the_ray_channel_runs_in_the_plain_c_host_with_an_empty_environment(fmu_dir, c_host, tmp_path):
    """The channel FMU set by a plain C host (no Python, an empty environment) to ``propagation = ray`` through a
    table profile, with no eigenray table (every eigenray solved), a diver 300 m out and 178 m below beacon 1: the
    travel time of beacon 1's packet is the eigenray's that the casadi model gives (:func:`rays.first_arrival`),
    not the straight line's."""
    from sblsim.models.acoustics.rays import first_arrival, profile_arrays

    values = {"beacon1_true_z": 2.0, "target_x": 300.0, "target_y": 40.0, "target_z": 180.0,
              "propagation": "ray", "sound_speed_rows": len(TABLE)}
    values.update({f"sound_speed_depth[{k + 1}]": row[0] for k, row in enumerate(TABLE)})
    values.update({f"sound_speed[{k + 1}]": row[1] for k, row in enumerate(TABLE)})
    got = run_channel(c_host, fmu_dir, tmp_path, values)
    first = np.flatnonzero(np.isclose(got["tx_time"], 0.1))[0]  # slot 1: beacon 1's packet
    nodes, speeds = profile_arrays(TABLE)
    x = math.hypot(300.0, 40.0)
    tau = float(first_arrival(1.0, 2.0, 180.0, x, 0.0, 1500.0, nodes, speeds)[0])
    assert got["travel_time"][first] == pytest.approx(tau, rel=1e-12)
    assert abs(tau - math.hypot(x, 178.0) / TABLE[:, 1].mean()) > 1e-5  # refraction shows


@pytest.mark.slow
def test_the_snr_channel_runs_in_the_plain_c_host_like_the_casadi_model_and_the_local_engine(fmu_dir, c_host,
                                                                                             tmp_path):
    """The channel FMU set by a plain C host (an empty environment) to ``detection = snr`` (eigenrays through a
    table profile, 400 m of water, a calm sea, a gravel floor), four beacons 10 m deep and a diver 300 m out and
    180 m deep, at a source level and fluctuation where some packets are heard on the direct path, some on the
    surface-reflected one and some are lost: every Real output of every step equals the local engine's (the same
    parameters and inputs) within 1e-9, and each packet's SNR, detection probability and travel time are those
    of its arrival that the casadi model of the site gives (:func:`~sblsim.models.acoustics.core.site_levels`)."""
    from sblsim.models.acoustics.channel.component import Acoustics
    from sblsim.models.acoustics.channel.site_levels import site_levels
    from sblsim.orchestrator.cosim.local_engine import LocalHandle

    table = "; ".join(f"{z:g} {c:g}" for z, c in TABLE)
    params = Acoustics.fmu_parameters({"propagation": "ray", "detection": "snr", "sound_speed_profile": "table",
                                       "sound_speed_table": table, "water_depth": 400.0, "bottom": "gravel",
                                       "beaufort": 0, "source_level": 126.0, "fluctuation": 6.0})
    beacons = np.array([[1.5, 0.0, 10.0], [0.0, 1.5, 10.0], [-1.5, 0.0, 10.0], [0.0, -1.5, 10.0]])
    target = np.array([300.0, 40.0, 180.0])
    inputs = {f"target_{a}": target[k] for k, a in enumerate("xyz")}
    for b, position in enumerate(beacons, start=1):
        for k, a in enumerate("xyz"):
            inputs[f"beacon{b}_true_{a}"] = inputs[f"beacon{b}_{a}"] = position[k]
    steps = 60
    got = run_channel(c_host, fmu_dir, tmp_path, {**params, **inputs}, steps)

    local = LocalHandle("acoustics")
    try:
        local.setup(params, [0])
        local.set_inputs({name: np.array([value]) for name, value in inputs.items()})
        records = []
        for k in range(steps):
            local.do_step(k * 0.1, 0.1)
            records.append({name: value[0] for name, value in local.get_outputs().items()})
    finally:
        local.close()
    for name, column in got.items():
        np.testing.assert_allclose(column, [r[name] for r in records], rtol=0, atol=1e-9, err_msg=name)

    levels = site_levels(params, beacons, np.tile(target, (4, 1)))
    new = np.flatnonzero(np.diff([0] + [r["packet_seq"] for r in records]))
    kinds = []
    for k in new:
        beacon, kind = records[k]["beacon_id"] - 1, records[k]["arrival"]
        family = kind - 1 if kind else int(np.argmax(levels["snr"][beacon]))  # none heard: the strongest
        assert got["snr"][k] == pytest.approx(levels["snr"][beacon, family], abs=1e-9)
        assert got["detection_probability"][k] == pytest.approx(levels["pd"][beacon, family], abs=1e-9)
        if kind:
            assert got["travel_time"][k] == pytest.approx(levels["tau"][beacon, family], rel=1e-12)
        kinds.append(kind)
    assert len(kinds) > 40 and {0, 1, 2} <= set(kinds)
