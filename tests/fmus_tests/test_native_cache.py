"""The local engine's compiled library, and a model's generated C, are found by a key of what they are generated
from."""

from __future__ import annotations

import sblsim.fmus.codegen as codegen
import sblsim.fmus.native as native
from sblsim.models import MODELS
from sblsim.models.systems import SYSTEMS, System


def test_a_process_finds_the_cached_library_without_generating_its_sources(monkeypatch):
    """Once the library is built, a new process (here: the lookup's caches cleared) gets the same library and
    generates no source (what cost every worker seconds of CPU)."""
    built = native.library_path(4)
    native.library_path.cache_clear()

    def refuse(*args, **kwargs):
        raise AssertionError("sources generated to find a cached library")

    monkeypatch.setattr(native, "write_library_sources", refuse)
    try:
        assert native.library_path(4) == built
    finally:
        native.library_path.cache_clear()


def test_the_key_hashes_the_generated_sources_when_a_model_or_system_is_not_the_packages(monkeypatch):
    """A user's model or a registered system from outside the package can change the generated code in ways the
    package's files do not show: then the key is the generated sources' hash (they are generated)."""
    assert codegen.built_in(tuple(MODELS.values()))

    class Mine(list(MODELS.values())[0]):
        pass

    assert not codegen.built_in((Mine,))
    monkeypatch.setitem(SYSTEMS, "mine", type("Mine", (System,), {})())
    assert not codegen.built_in(tuple(MODELS.values()))


def test_the_package_digest_covers_the_model_and_runtime_sources(monkeypatch, tmp_path):
    """The digest changes when the runtime's C changes (a copy of the folder with one byte more)."""
    before = codegen.package_digest()
    copy = tmp_path / "c"
    copy.mkdir()
    for path in codegen.C_DIR.iterdir():
        if path.is_file():
            (copy / path.name).write_bytes(path.read_bytes())
    (copy / "sblsim_runtime.h").write_bytes((copy / "sblsim_runtime.h").read_bytes() + b"\n")
    codegen.package_digest.cache_clear()
    monkeypatch.setattr(codegen, "C_DIR", copy)
    try:
        assert codegen.package_digest() != before
    finally:
        codegen.package_digest.cache_clear()


def test_libraries_of_other_models_share_their_objects(monkeypatch, tmp_path):
    """A library of one model is made of the runtime's, the bound's, the eigenray functions' and that model's
    objects and no other model's; the library of no model (the metrics' and the bounds') is another file made of
    the same objects but the model's and the registry's: the objects are the compiler cache's, shared (here the
    suite's cache; the libraries go to a folder of their own)."""
    import sblsim.fmus.compiler as compiler

    used = []
    objects = compiler._objects

    def recording(*args, **kwargs):
        paths = objects(*args, **kwargs)
        used.append({path.name: source.name for path, source in zip(paths, args[2])})
        return paths

    monkeypatch.setattr(compiler, "_objects", recording)
    monkeypatch.setattr(native, "cache_dir", lambda: tmp_path)
    native.library_path.cache_clear()
    try:
        one = native.library_path(4, models=(MODELS["target"],))
        none = native.library_path(4, models=native.NO_MODELS)
    finally:
        native.library_path.cache_clear()
    assert none != one and none.is_file() and one.parent == none.parent == tmp_path
    (first, second) = used
    sources = set(first.values())
    assert {"sblsim_target_casadi.c", "sblsim_ray_points.c", "sblsim_bound_casadi.c"} <= sources
    assert not any(name.startswith(("sblsim_receiver", "sblsim_acoustics", "sblsim_platform")) for name in sources)
    shared = set(first) & set(second)
    assert {first[o] for o in set(first) - shared} == {"sblsim_target_casadi.c", "sblsim_target_model.c",
                                                      "sblsim_models.c"}
    assert {second[o] for o in set(second) - shared} == {"sblsim_models.c"}


def test_a_run_s_local_handles_share_the_library_of_the_models_it_runs():
    """The paper's system on the local engine: the four components' handles run in one library of their four
    models (no other receiver compiled), and a user's model in a library of its own."""
    from sblsim.orchestrator.cosim.engines import make_handles
    from sblsim.orchestrator.cosim.handles import paper_sources

    handles = make_handles("local")
    paper = tuple(MODELS[name] for name in ("platform", "acoustics", "target", "receiver"))
    assert {handle.library for handle in handles.values()} == {paper}

    class Mine(MODELS["receiver"]):
        pass

    handles = make_handles("local", sources={**paper_sources(), "receiver": Mine})
    assert handles["receiver"].library is None and handles["platform"].library == paper[:3]


def test_generated_code_is_kept_between_processes_for_built_in_models_only(monkeypatch, tmp_path):
    """A process that needs a built-in model's generated C (an FMU's build, its GUID) reads what an earlier one
    generated, the same text as casadi generates it; a user's model is always generated; a cache that cannot be
    read or written is generated around."""
    monkeypatch.setenv("SBLSIM_CACHE_DIR", str(tmp_path / "cache"))
    target = MODELS["target"]
    codegen.casadi_code.cache_clear()
    try:
        generated = codegen.casadi_code(target, 3)
        kept = codegen._code_cache(target, 3)
        assert kept.parent == tmp_path / "cache" / "code"
        assert (kept.with_suffix(".c").read_text(), kept.with_suffix(".h").read_text()) == generated
        assert not list(kept.parent.glob(".*partial"))
        codegen.casadi_code.cache_clear()  # a new process: what the cache holds is what it gets
        kept.with_suffix(".c").write_text(generated[0] + "/* kept */\n")
        assert codegen.casadi_code(target, 3)[0].endswith("/* kept */\n")
        codegen.casadi_code.cache_clear()  # the header missing: generated again, and kept again
        kept.with_suffix(".h").unlink()
        assert codegen.casadi_code(target, 3) == generated
        assert kept.with_suffix(".h").read_text() == generated[1]

        class Mine(target):
            pass

        assert codegen._code_cache(Mine, 3) is None
        assert codegen._code_cache(target, 4) != kept  # the beacon count is in the key
        codegen.casadi_code.cache_clear()  # a cache folder that is a file: nothing kept, the code still made
        (tmp_path / "blocked").write_text("")
        monkeypatch.setenv("SBLSIM_CACHE_DIR", str(tmp_path / "blocked"))
        assert codegen.casadi_code(target, 3) == generated
    finally:
        codegen.casadi_code.cache_clear()
