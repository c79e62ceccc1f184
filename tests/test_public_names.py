"""Every ``__all__`` of the package lists only names its module defines (``from sblsim.x import *`` works)."""

from __future__ import annotations

import importlib
import pkgutil

import pytest

import sblsim.fmus
import sblsim.models
import sblsim.orchestrator


def _modules() -> list[str]:
    names = []
    for package in (sblsim.models, sblsim.fmus, sblsim.orchestrator):
        names.append(package.__name__)
        names += [m.name for m in pkgutil.walk_packages(package.__path__, package.__name__ + ".")]
    return sorted(names)


MODULES = _modules()


def test_every_module_is_found():
    assert {"sblsim.models", "sblsim.models.errors", "sblsim.orchestrator.cli", "sblsim.fmus.build",
            "sblsim.orchestrator.campaign.errors"} <= set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_all_lists_only_names_that_exist(name):
    module = importlib.import_module(name)
    listed = getattr(module, "__all__", [])
    assert [n for n in listed if not hasattr(module, n)] == []
    assert len(set(listed)) == len(listed)
    namespace: dict = {}
    exec(f"from {name} import *", namespace)  # noqa: S102 - the statement a user writes
    assert set(listed) <= set(namespace)
