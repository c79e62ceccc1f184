"""The study record: a study as a campaign's results record it (``study.toml``) or as the analysis infers it,
read without the scenarios (:class:`StudyRecord`, :func:`read_record`).

The study itself (its file, validated against the scenarios) is :mod:`sblsim.orchestrator.campaign.study`'s.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sblsim.orchestrator.campaign.errors import StudyError
from sblsim.orchestrator.campaign.study import Factor
from sblsim.orchestrator.io import tomlfile


@dataclass
class StudyRecord:
    """A study as its results record it (``study.toml`` of a campaign), or as inferred from ``runs.parquet``.

    Unlike :class:`Study` it is not validated against the scenarios (they may
    live on another machine); it is what the analysis needs.

    Attributes
    ----------
    name : str
    seed : int or None
        Campaign seed.
    replicates : int or None
        Runs per design cell.
    design : str
        ``full``, ``fractional`` or ``unknown`` (inferred).
    resolution : int
        Resolution of a fractional design (0 otherwise).
    generators : str
        Generators of a fractional design.
    scenarios : list of str
    engine : str
    factors : list of Factor
        In design order.
    inferred : bool
        True when there was no ``study.toml``.
    """

    name: str
    seed: int | None
    replicates: int | None
    design: str
    resolution: int
    generators: str
    scenarios: list[str]
    engine: str
    factors: list[Factor]
    inferred: bool = False


def level_value(value: Any) -> float | str:
    """A factor level as read from a file: a number, or the text of a text key (e.g. ``ekf-seq``)."""
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return float(value)


def read_record(path: Path | str, name: str = "study", scenarios: list[str] | None = None) -> StudyRecord:
    """Read a campaign's ``study.toml`` (the table :meth:`Study.to_dict` writes, with its ``[execution]``).

    Parameters
    ----------
    path : path
    name, scenarios
        Defaults for a file that does not record them.

    Raises
    ------
    StudyError
        If the file cannot be parsed or an entry is malformed (one line naming the file).
    """
    path = Path(path)
    try:
        raw = tomlfile.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise StudyError(f"study.toml: cannot parse {str(path)!r} ({str(exc).splitlines()[0]})") from None
    s = raw.get("study", {})
    try:
        factors = [Factor(name=str(f["name"]), key=str(f.get("key", "")), low=level_value(f["low"]),
                          high=level_value(f["high"]), unit=str(f.get("unit", "")),
                          description=str(f.get("description", "")))
                   for f in raw.get("factors", [])]
        return StudyRecord(name=str(s.get("name", name)), seed=int(s["seed"]) if "seed" in s else None,
                           replicates=int(s["replicates"]) if "replicates" in s else None,
                           design=str(s.get("design", "full")), resolution=int(s.get("resolution", 0)),
                           generators=str(s.get("generators", "")),
                           scenarios=[str(x) for x in s.get("scenarios", scenarios or [])],
                           engine=str(raw.get("execution", {}).get("engine", s.get("engine", ""))),
                           factors=factors)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise StudyError(f"study.toml: invalid entry in {str(path)!r} ({type(exc).__name__}: {exc})") from None


__all__ = ["StudyRecord", "level_value", "read_record"]
