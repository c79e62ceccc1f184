"""Variable declarations: validation of values against type and allowed range."""

import math

import pytest

from models.core import ModelError, Variable, resolve_parameters

REAL = Variable("baseline", "parameter", "Real", 1.0, "m", min=0.0, max=10.0, min_exclusive=True)
INTEGER = Variable("beaufort", "parameter", "Integer", 2, min=0, max=8)
CHOICE = Variable("gps_model", "parameter", "String", "white", choices=("white", "gauss-markov"))


@pytest.mark.parametrize("var", [REAL, INTEGER])
@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_non_finite_values_are_refused_with_the_field_name(var, value):
    with pytest.raises(ModelError, match=f"^platform.{var.name}: .*not finite"):
        var.coerce(value, f"platform.{var.name}")


def test_range_bounds_follow_the_declaration():
    assert REAL.coerce(10, "b") == 10.0 and isinstance(REAL.coerce(10, "b"), float)
    with pytest.raises(ModelError, match=r"\(0, 10\] m"):
        REAL.coerce(0.0, "b")  # exclusive lower bound
    with pytest.raises(ModelError, match=r"\(0, 10\] m"):
        REAL.coerce(10.000001, "b")
    assert INTEGER.coerce(8.0, "k") == 8 and isinstance(INTEGER.coerce(8.0, "k"), int)
    with pytest.raises(ModelError, match="whole number"):
        INTEGER.coerce(2.5, "k")
    with pytest.raises(ModelError, match="expected a number"):
        INTEGER.coerce(True, "k")  # a boolean is not a number here


def test_choices_and_unknown_parameters():
    assert CHOICE.coerce("gauss-markov", "g") == "gauss-markov"
    with pytest.raises(ModelError, match="one of white, gauss-markov"):
        CHOICE.coerce("pink", "g")
    with pytest.raises(ModelError, match="^platform.nope: unknown parameter"):
        resolve_parameters((REAL, INTEGER), {"nope": 1}, "platform")
    assert resolve_parameters((REAL, INTEGER), {}, "platform") == {"baseline": 1.0, "beaufort": 2}


def test_declaration_rejects_an_undeclared_unit():
    with pytest.raises(ValueError, match="unit"):
        Variable("x", "output", "Real", 0.0, "furlong")
