"""The campaign's exceptions."""

from __future__ import annotations

from pathlib import Path

from sblsim.models.declarations import ModelError


class CampaignError(ModelError):
    """Invalid campaign request (output directory, scheduler, engine)."""


class CampaignInterrupted(Exception):
    """The campaign was interrupted; finished chunks are on disk."""

    def __init__(self, done: int, total: int, out: Path) -> None:
        super().__init__(f"interrupted: {done} of {total} runs saved in {out}; finish with --resume")
        self.done, self.total, self.out = done, total, out
