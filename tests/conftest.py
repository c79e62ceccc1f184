"""Shared fixtures of the sblsim test suite."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory):
    """Directory holding the FMUs (one per model of ``models.MODELS``) freshly built with ``build_all``.

    Session-scoped and lazy: the FMUs are built once, and only when a test
    asks for this fixture.
    """
    from sblsim.fmus.build import build_all
    from sblsim.models import MODELS

    directory = tmp_path_factory.mktemp("fmus")
    paths = build_all(directory)
    assert sorted(p.name for p in paths) == sorted(f"sblsim_{n}.fmu" for n in MODELS)
    assert all(p.is_file() for p in paths)
    return directory
