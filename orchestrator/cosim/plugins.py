"""User plugins: a user's receiver model written in Python (``simulation.receiver = "model:PATH.py"``)."""

from __future__ import annotations

import hashlib
import importlib.util
import re
from functools import lru_cache
from pathlib import Path

from sblsim.models import COMPONENTS, MODELS, RECEIVERS
from sblsim.models.component import Component
from sblsim.models.declarations import ModelError
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.cosim.connections import check_interface
from sblsim.orchestrator.cosim.handles import Port


@lru_cache(maxsize=None)
def _user_model(path: str, stamp: tuple[int, int]) -> type:
    where = "simulation.receiver"
    name = "sblsim_user_" + hashlib.sha256(path.encode()).hexdigest()[:12]
    try:
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    except (Exception, SystemExit) as exc:  # a user's module may raise anything on import, even sys.exit(0)
        raise ConfigError(f"{where}: cannot import {path!r} (it raised {type(exc).__name__}: {exc})") from None
    found = [c for c in vars(module).values()
             if isinstance(c, type) and issubclass(c, Component) and c.__module__ == name]
    if len(found) != 1:
        raise ConfigError(f"{where}: {path!r} defines {len(found)} model classes "
                          f"({', '.join(c.__name__ for c in found) or 'none'}); it must define exactly one receiver")
    model = found[0]
    if not re.fullmatch(r"receiver_[A-Za-z0-9_]+", str(getattr(model, "name", ""))) or model.name in MODELS:
        raise ConfigError(f"{where}: {model.__name__}.name = {getattr(model, 'name', None)!r} must be 'receiver_' + "
                          f"letters, digits or '_', and not a built-in's ({', '.join(RECEIVERS.values())})")
    try:
        variables = model.fmu_variables()
        model.program()
    except (Exception, SystemExit) as exc:
        raise ConfigError(f"{where}: {model.__name__} in {path!r} does not build ({type(exc).__name__}: {exc})") \
            from None
    try:
        check_interface("receiver", [Port(v.name, v.causality, v.fmi_type, v.unit) for v in variables],
                        COMPONENTS["receiver"].fmu_variables(), f"{model.__name__} in {path!r}")
    except ModelError as exc:
        raise ConfigError(f"{where}: {str(exc).split(': ', 1)[1]}") from None
    return model


def user_model(path: str | Path) -> type:
    """The receiver model (a :class:`sblsim.models.component.Component`) that a user's Python file defines.

    The file must define exactly one model class whose ``name`` is
    ``receiver_…`` (not a built-in's) and whose inputs and outputs are the
    receiver interface. Loaded once per file version.

    Raises
    ------
    ConfigError
        If the file is missing, does not import (any exception, or ``SystemExit``, raised while importing
        it), or its model is not a receiver.
    """
    path = Path(path)
    if not path.is_file() or path.suffix != ".py":
        raise ConfigError(f"simulation.receiver: no Python file at {str(path)!r} (model:PATH.py)")
    st = path.stat()
    return _user_model(str(path.resolve()), (st.st_mtime_ns, st.st_size))
