"""sblsim: co-simulation of acoustic underwater positioning (SBL, LBL, USBL) with FMI 2.0 components.

The public Python API (:data:`__all__`); the documentation's API reference describes every name::

    import sblsim

    r = sblsim.run("semicircle", seed=1)     # what `sblsim run semicircle --seed 1` computes
    r.summary["e_tot_rms"]                   # [m]
    r.timeseries                             # pandas.DataFrame, the columns of timeseries.parquet
    figures = r.plot()                       # matplotlib figures

Importing ``sblsim`` is cheap: the functions load numpy, pandas, casadi and matplotlib when first called.
The implementation is :mod:`sblsim.orchestrator.api`; the subpackages ``sblsim.models``, ``sblsim.fmus`` and
``sblsim.orchestrator`` are the project's internals (no promise of stability).

This file is the package ``sblsim`` itself: the project's top-level folders are installed as its
subpackages (``package-dir`` in ``pyproject.toml``).
"""

from __future__ import annotations

from sblsim.orchestrator.io.version import installed_version as _installed_version

__all__ = [
    "load", "run", "compare", "map", "accuracy_map", "budget", "design", "replay", "replay_toa", "replay_toa_tags",
    "calibrate", "campaign", "analyze", "Config", "RunResult", "CompareResult", "MapResult", "BudgetResult",
    "DesignResult", "ReplayResult", "TrackResult", "TagsResult", "store", "StoreResult", "sync", "SyncResult",
    "toa", "ToaResult", "track",
    "StudyResult",
    "CalibrationResult", "CampaignResult", "AnalysisResult", "SblsimError", "ConfigError", "ENGINES",
    "BUILTIN_SCENARIOS", "__version__",
]


def __getattr__(name: str) -> object:
    """The public names, imported from :mod:`sblsim.orchestrator.api` when first used."""
    if name == "__version__":
        return _installed_version()
    if name in __all__:
        from sblsim.orchestrator import api

        value = getattr(api, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'sblsim' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
