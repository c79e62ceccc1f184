"""The installed distribution's version, as ``pip show sblsim`` gives it: for ``sblsim --version``,
``sblsim.__version__`` and the pages that record which sblsim wrote them."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

#: What a checkout that was never installed calls its version.
NOT_INSTALLED = "unknown (not installed)"


def installed_version() -> str:
    """The version of the installed ``sblsim`` distribution, or :data:`NOT_INSTALLED`."""
    try:
        return version("sblsim")
    except PackageNotFoundError:  # run from a checkout that was never installed
        return NOT_INSTALLED
