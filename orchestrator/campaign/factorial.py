"""The design matrix of a study: the coded (−1/+1) 2-level full factorial, or pyDOE3's fractional factorial.

Row ``c`` of the matrix is design cell ``c`` (the full factorial in the rows of pyDOE3's ``ff2n``: the first
factor changes slowest). pyDOE3 is imported only for a fractional design: its import loads scipy.stats, which a
campaign's workers never need.

References
----------
Montgomery, Design and Analysis of Experiments, 9th ed., Wiley 2017, chapters 6 (2^k designs) and 8 (2^(k-p)
fractional designs).
"""

from __future__ import annotations

import numpy as np

from sblsim.orchestrator.campaign.errors import StudyError


def full_factorial(k: int) -> np.ndarray:
    """The coded 2-level full factorial of ``k`` factors, shape (2^k, k), in the rows of pyDOE3's ``ff2n`` (cell c's
    factor j at +1 where bit k − 1 − j of c is set: the first factor varies slowest). Written here because pyDOE3's
    import loads scipy.stats, half a second of every campaign's start for a table of signs;
    ``tests/orchestrator/test_campaign.py`` compares it with ``ff2n``."""
    cells = np.arange(2 ** k, dtype=np.int64)[:, None]
    return np.where((cells >> np.arange(k - 1, -1, -1)) & 1, 1, -1).astype(np.int64)


def design_matrix(k: int, design: str = "full", resolution: int = 0, generators: str = "") -> np.ndarray:
    """Coded 2-level design matrix: the full factorial (:func:`full_factorial`, pyDOE3's rows) or pyDOE3's
    fractional one.

    Parameters
    ----------
    k : int
        Number of factors.
    design : {'full', 'fractional'}
    resolution : int
        Fractional: lowest resolution wanted (pyDOE3 ``fracfact_by_res``).
    generators : str
        Fractional: explicit generator string (pyDOE3 ``fracfact``, e.g.
        ``"a b c abc"``); takes precedence over ``resolution``.

    Returns
    -------
    ndarray of int, shape (cells, k)

    Raises
    ------
    StudyError
        If the design cannot be built.
    """
    if design == "full":
        return full_factorial(k)
    import pyDOE3  # here, not at the top: it imports scipy.stats (a second), which a campaign's workers never need

    if generators:
        words = generators.split()
        if len(words) != k:
            raise StudyError(f"study.generators: {len(words)} generators for {k} factors; give one per factor")
        try:
            matrix = pyDOE3.fracfact(generators)
        except Exception as exc:  # pyDOE3 raises plain exceptions on bad strings
            raise StudyError(f"study.generators: {generators!r} is not a valid generator string ({exc})") from None
        return np.asarray(matrix).astype(np.int64)
    if resolution < 3:
        raise StudyError(f"study.resolution: {resolution} is outside the allowed range [3, {k}] "
                         "(or give study.generators)")
    try:
        return np.asarray(pyDOE3.fracfact_by_res(k, resolution)).astype(np.int64)
    except ValueError as exc:
        raise StudyError(f"study.resolution: no 2-level design of resolution {resolution} for {k} factors "
                         f"({exc})") from None


__all__ = ["design_matrix", "full_factorial"]
