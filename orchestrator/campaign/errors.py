"""The campaign's exceptions: :class:`CampaignError` (the error kind of :mod:`sblsim.models.errors`),
:class:`StudyError` (an invalid study, a configuration error) and :class:`CampaignInterrupted` (an interruption, not
an error: finished work is kept)."""

from __future__ import annotations

from pathlib import Path

from sblsim.models.errors import CampaignError, ConfigError


class StudyError(ConfigError):
    """Invalid study; the message names the field and the allowed range."""


class CampaignInterrupted(Exception):
    """The campaign was interrupted; finished chunks are on disk."""

    def __init__(self, done: int, total: int, out: Path) -> None:
        super().__init__(f"interrupted: {done} of {total} runs saved in {out}; finish with --resume")
        self.done, self.total, self.out = done, total, out


__all__ = ["CampaignError", "CampaignInterrupted", "StudyError"]
