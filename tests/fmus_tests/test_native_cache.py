"""The local engine's compiled library is found by a key of what its sources are generated from."""

from __future__ import annotations

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
    assert native._built_in(None) and native._built_in(tuple(MODELS.values()))

    class Mine(list(MODELS.values())[0]):
        pass

    assert not native._built_in((Mine,))
    monkeypatch.setitem(SYSTEMS, "mine", type("Mine", (System,), {})())
    assert not native._built_in(None)


def test_the_package_digest_covers_the_model_and_runtime_sources(monkeypatch, tmp_path):
    """The digest changes when the runtime's C changes (a copy of the folder with one byte more)."""
    before = native._package_digest()
    copy = tmp_path / "c"
    copy.mkdir()
    for path in native.C_DIR.iterdir():
        if path.is_file():
            (copy / path.name).write_bytes(path.read_bytes())
    (copy / "sblsim_runtime.h").write_bytes((copy / "sblsim_runtime.h").read_bytes() + b"\n")
    native._package_digest.cache_clear()
    monkeypatch.setattr(native, "C_DIR", copy)
    try:
        assert native._package_digest() != before
    finally:
        native._package_digest.cache_clear()
