"""The kinds of error sblsim raises, one class per kind under one root.

Every error sblsim raises on purpose derives from :class:`SblsimError`, so a
caller catches all of them with one ``except SblsimError``, or one kind by
its class. Every message is one line that names the field, file or call at
fault (the command line prints it as it is and exits with status 2)::

    SblsimError
    ├── ModelError        an invalid parameter, value or input (also a ValueError)
    │   └── ConfigError   an invalid configuration (a TOML file, --set, a study file)
    ├── FMICallError      an FMI function of an FMU returned a failure
    ├── CompileError      the C compiler failed or is missing
    ├── ArchiveError      an archive (FMU, SSP package) that is not safe or not valid
    └── CampaignError     a campaign that cannot run, resume or be analysed as asked

The modules that raise an error kind also name it (``sblsim.models.declarations.ModelError``,
``sblsim.orchestrator.cosim.config.ConfigError``, ``sblsim.fmus.compiler.CompileError``,
``sblsim.orchestrator.io.archives.ArchiveError``, ``sblsim.orchestrator.campaign.CampaignError``);
they are the same classes. More specific errors derive from these kinds where they are raised:
``StudyError`` (a :class:`ConfigError`), ``ConnectionMismatch`` (a :class:`ModelError`), ``SspError``
(an :class:`ArchiveError`) and ``AnalysisError`` (a :class:`CampaignError`).

:class:`ModelError` stays a :class:`ValueError` as it always was (code that catches ``ValueError`` for
a bad value keeps working); the other kinds are not value errors.
"""

from __future__ import annotations


class SblsimError(Exception):
    """The root of every error sblsim raises on purpose; the message is one line."""


class ModelError(SblsimError, ValueError):
    """A parameter or input of a component is invalid.

    The message is one line and names the offending field and its allowed
    range, so the command line can show it as it is.
    """


class ConfigError(ModelError):
    """Invalid configuration; the message names the field and the allowed range."""


class FMICallError(SblsimError):
    """An FMI function of an FMU returned a failure status (as FMPy's ``FMICallException``).

    Parameters
    ----------
    message : str
        The one-line message (it names the FMU, the function, the status and the FMU's log).
    function : str
        The FMI function, e.g. ``fmi2DoStep``.
    status : int or None
        What it returned (``fmi2Status``: 2 discard, 3 error, 4 fatal); None when the function returns no status
        (``fmi2Instantiate`` returns no instance instead).
    log : str
        What the FMU logged about the failure (empty: nothing).

    Attributes
    ----------
    function, status, log
        As given.
    """

    def __init__(self, message: str, function: str = "", status: int | None = None, log: str = "") -> None:
        super().__init__(message)
        self.function, self.status, self.log = function, status, log


class CompileError(SblsimError):
    """The C compiler failed or is missing; the message says which and why."""


class ArchiveError(SblsimError):
    """An archive that is not safe or not valid to unpack or read; the message is one line."""


class CampaignError(SblsimError):
    """A campaign request that cannot be carried out (output directory, resume, scheduler, engine, analysis)."""


__all__ = ["ArchiveError", "CampaignError", "CompileError", "ConfigError", "FMICallError", "ModelError",
           "SblsimError"]
