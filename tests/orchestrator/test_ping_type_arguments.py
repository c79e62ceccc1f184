"""The ping type's arguments have one check (:func:`sblsim.orchestrator.tracks.options.ping_type_arguments`) for the
tracking (``sblsim replay --format toa``, ``sblsim.replay_toa``) and for ``sblsim toa`` (``stated``): each refusal
worded as its command words it, and the one rule that differs (``sblsim toa`` takes a burst interval or sequence only
with its ping type named; the tracking infers the type) kept apart."""

from __future__ import annotations

from pathlib import Path

import pytest

from sblsim.models.errors import ConfigError
from sblsim.orchestrator.tracks.options import ping_type_arguments

NAMES = ("--ping-type", "--burst-interval", "--burst-sequence")
TOA = {"stated": True, "example": "60:120"}


@pytest.mark.parametrize("args, options, message", [
    (("rbi", "40:20", None), {}, "--burst-interval: '40:20'; allowed: MIN:MAX [s] with 0.1 <= MIN <= MAX <= 86400, "
                                 "e.g. 20:40"),
    (("rbi", "40:20", None), TOA, "--burst-interval: '40:20'; allowed: MIN:MAX [s] with 0.1 <= MIN <= MAX <= 86400, "
                                  "e.g. 60:120"),
    ((None, "20:40", None), TOA, "--burst-interval: only with --ping-type rbi (a random burst interval)"),
    (("sbi", "20:40", None), {}, "--burst-interval: only with a random burst interval (--ping-type rbi)"),
    (("sbi", None, "s.txt"), TOA, "--burst-sequence: only with --ping-type pbi (a pseudo-random burst interval)"),
    (("rbi", None, "s.txt"), {}, "--burst-sequence: only with a pseudo-random burst interval (--ping-type pbi)"),
    ((None, "20:40", "s.txt"), {}, "--burst-interval: not with --burst-sequence (one ping type: rbi or pbi)"),
    (("pbi", None, None), {}, "--ping-type pbi: needs --burst-sequence (the tag's intervals [s], one per row)"),
    (("pbi", None, None), TOA, "--ping-type pbi: needs --burst-sequence (the tag's intervals [s], one per row)"),
    (("xyz", None, None), TOA, "--ping-type: 'xyz'; allowed: sbi, rbi, pbi"),
    (("rbi", 5, None), {}, "--burst-interval: int; allowed:"),
    (("rbi", 5, None), TOA, "--burst-interval: '5'; allowed:"),
    (("pbi", None, 5), TOA, "--burst-sequence: int; allowed: a file (a text or a path)"),
])
def test_each_command_s_refusal_is_its_own(args, options, message):
    with pytest.raises(ConfigError) as error:
        ping_type_arguments(*args, NAMES, **options)
    assert str(error.value).startswith(message) and "\n" not in str(error.value)


def test_what_each_command_takes():
    """The tracking takes an interval without a ping type (inferred), ``sblsim toa`` a pair ``float`` reads; both
    return the interval [s] as floats and the sequence as a path."""
    assert ping_type_arguments(None, "20:40", None, NAMES) == (None, (20.0, 40.0), None)
    assert ping_type_arguments("rbi", ("60", "120"), None, NAMES, **TOA) == ("rbi", (60.0, 120.0), None)
    with pytest.raises(ConfigError, match="^--burst-interval: "):
        ping_type_arguments("rbi", ("60", "120"), None, NAMES)
    assert ping_type_arguments("pbi", None, "s.txt", NAMES, **TOA) == ("pbi", None, Path("s.txt"))
    assert ping_type_arguments("pbi", None, Path("s.txt"), NAMES) == ("pbi", None, Path("s.txt"))
