"""Declarations: values against type and range, table text, choices as FMU integers, parameter vectors.

References are hand-worked: expected messages and vectors written out for a
small declaration set, tables checked against the values they were written
from.
"""

import math

import numpy as np
import pytest

from sblsim.models.component import Component
from sblsim.models.declarations import Column, ModelError, Table, Variable, resolve_parameters
from sblsim.models.platform import Platform
from sblsim.models.table_text import format_table, parse_table
from sblsim.models.target import Target
from sblsim.models.target.core import WAYPOINTS

REAL = Variable("baseline", "parameter", "Real", 1.0, "m", min=0.0, max=10.0, min_exclusive=True)
INTEGER = Variable("beaufort", "parameter", "Integer", 2, min=0, max=8)
CHOICE = Variable("gps_model", "parameter", "String", "white", choices=("white", "gauss-markov"))
FLAG = Variable("enabled", "parameter", "Boolean", False)

TABLE = Table(columns=(Column("t", "s", "time", 0.0, 100.0), Column("c", "m/s", "speed", 1400.0, 1600.0)),
              max_rows=3, increasing=True)


# ----------------------------------------------------------------------------
# Variable.coerce
# ----------------------------------------------------------------------------

@pytest.mark.parametrize("var", [REAL, INTEGER])
@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_non_finite_values_are_refused_with_the_field_name(var, value):
    with pytest.raises(ModelError, match=f"^platform.{var.name}: .*not finite"):
        var.coerce(value, f"platform.{var.name}")


def test_range_bounds_follow_the_declaration():
    assert REAL.coerce(10, "b") == 10.0 and isinstance(REAL.coerce(10, "b"), float)
    assert REAL.coerce(np.float32(0.5), "b") == 0.5
    with pytest.raises(ModelError, match=r"\(0, 10\] m"):
        REAL.coerce(0.0, "b")  # exclusive lower bound
    with pytest.raises(ModelError, match=r"\(0, 10\] m"):
        REAL.coerce(10.000001, "b")
    assert INTEGER.coerce(8.0, "k") == 8 and isinstance(INTEGER.coerce(8.0, "k"), int)
    assert INTEGER.coerce(np.int64(0), "k") == 0
    with pytest.raises(ModelError, match=r"^k: -1 is outside the allowed range \[0, 8\]$"):
        INTEGER.coerce(-1, "k")
    with pytest.raises(ModelError, match="whole number"):
        INTEGER.coerce(2.5, "k")
    with pytest.raises(ModelError, match="expected a number"):
        INTEGER.coerce(True, "k")  # a boolean is not a number here
    with pytest.raises(ModelError, match="expected a number"):
        REAL.coerce("1.5", "b")  # nor is text


@pytest.mark.parametrize("var", [REAL, INTEGER])
@pytest.mark.parametrize("value", [10**400, -(10**400)])
def test_a_huge_integer_is_a_range_error_not_an_overflow(var, value):
    """float(10**400) overflows; the check reports the allowed range instead of an OverflowError."""
    with pytest.raises(ModelError, match=rf"^platform\.{var.name}: .* is outside the allowed range "
                                         + (r"\(0, 10\] m$" if var is REAL else r"\[0, 8\]$")):
        var.coerce(value, f"platform.{var.name}")


def test_booleans_accept_only_true_or_false():
    assert FLAG.coerce(True) is True and FLAG.coerce(np.bool_(False)) is False
    for bad in (1, 0.0, "true"):
        with pytest.raises(ModelError, match="expected true or false"):
            FLAG.coerce(bad, "x")
    assert FLAG.fmi_type == "Boolean" and FLAG.code(True) == 1.0


def test_choices_and_unknown_parameters():
    assert CHOICE.coerce("gauss-markov", "g") == "gauss-markov"
    with pytest.raises(ModelError, match="one of white, gauss-markov"):
        CHOICE.coerce("pink", "g")
    with pytest.raises(ModelError, match="expected text"):
        CHOICE.coerce(1, "g")
    with pytest.raises(ModelError, match="^platform.nope: unknown parameter"):
        resolve_parameters((REAL, INTEGER), {"nope": 1}, "platform")
    assert resolve_parameters((REAL, INTEGER), {}, "platform") == {"baseline": 1.0, "beaufort": 2}
    assert resolve_parameters((REAL, INTEGER, CHOICE), {"beaufort": 5.0, "gps_model": "gauss-markov"}) == {
        "baseline": 1.0, "beaufort": 5, "gps_model": "gauss-markov"}
    with pytest.raises(ModelError, match=r"^platform\.beaufort: 9 is outside"):
        resolve_parameters((REAL, INTEGER), {"beaufort": 9}, "platform")


def test_a_choice_is_an_integer_in_the_fmu():
    assert CHOICE.fmi_type == "Integer"
    assert CHOICE.fmi_start == 0
    assert Variable("m", "parameter", "String", "gauss-markov", choices=CHOICE.choices).fmi_start == 1
    assert CHOICE.code("gauss-markov") == 1.0 and CHOICE.code("white") == 0.0
    assert CHOICE.fmi_description().endswith("(0: white, 1: gauss-markov)")
    assert CHOICE.allowed() == "one of white, gauss-markov"
    assert CHOICE.variability == "fixed"
    # a choice declared by a component: the FMU variable is an Integer with the index of the start
    target = {v.name: v for v in Target.fmu_variables()}
    assert target["trajectory"].fmi_type == "Integer"
    assert target["trajectory"].choices[target["trajectory"].fmi_start] == "semicircle"


def test_allowed_range_text():
    assert REAL.allowed() == "(0, 10] m"
    assert INTEGER.allowed() == "[0, 8]"
    assert FLAG.allowed() == "true or false"
    assert Variable("x", "output", "Real", 0.0, "rad").allowed() == "(-inf, inf) rad"
    assert Variable("y", "parameter", "Real", 0.0, "1", min=-1.0).allowed() == "[-1, inf)"


def test_declaration_rejects_an_undeclared_unit_and_inconsistent_declarations():
    with pytest.raises(ValueError, match="unit"):
        Variable("x", "output", "Real", 0.0, "furlong")
    with pytest.raises(ValueError, match="causality"):
        Variable("x", "local", "Real", 0.0, "m")
    with pytest.raises(ValueError, match="free-text String"):
        Variable("path", "parameter", "String", "")  # free text cannot be an FMU variable
    assert Variable("path", "parameter", "String", "", scope="config").in_fmu is False
    with pytest.raises(ValueError, match="row count of a table is an Integer"):
        Variable("rows", "parameter", "Real", 0.0, "1", table=TABLE)


def test_variability_of_signals():
    assert Variable("x", "output", "Real", 0.0, "m").variability == "continuous"
    assert Variable("x", "output", "Real", 0.0, "m", discrete=True).variability == "discrete"
    assert Variable("n", "output", "Integer", 0).variability == "discrete"


# ----------------------------------------------------------------------------
# Tables
# ----------------------------------------------------------------------------

def test_parse_table_reads_rows_and_values():
    rows = parse_table("0 1500; 10.5,1501.25 ;  20 , 1499;", TABLE, "w")
    np.testing.assert_array_equal(rows, [[0.0, 1500.0], [10.5, 1501.25], [20.0, 1499.0]])
    assert parse_table("  ", TABLE, "w").shape == (0, 2)
    assert parse_table("", TABLE, "w").shape == (0, 2)
    # format_table writes 17 digits: the text reads back exactly
    values = np.array([[1 / 3, 1400 + 1 / 7], [2 / 3, 1600.0]])
    np.testing.assert_array_equal(parse_table(format_table(values), TABLE, "w"), values)


@pytest.mark.parametrize("text,message", [
    ("0 1500; 10 1500 3", r"^sec\.tab: row 2 has 3 values, expected 2 \(t c\)$"),
    ("0 1500; 10", r"^sec\.tab: row 2 has 1 values, expected 2 \(t c\)$"),
    ("0 1500; 10 fast", r"^sec\.tab: row 2, column c: 'fast' is not a number$"),
    ("nan 1500", r"^sec\.tab: row 1, column t: nan is not finite; allowed \[0, 100\] s$"),
    ("0 1500; 1 inf", r"^sec\.tab: row 2, column c: inf is not finite"),
    ("0 1500; 1 1300", r"^sec\.tab: row 2, column c: 1300 is outside the allowed range \[1400, 1600\] m/s$"),
    ("-1 1500", r"^sec\.tab: row 1, column t: -1 is outside the allowed range \[0, 100\] s$"),
    ("0 1500; 5 1500; 5 1500", r"^sec\.tab: row 3, column t: must be greater than the row before$"),
    ("0 1500; 5 1500; 4 1500", r"^sec\.tab: row 3, column t: must be greater than the row before$"),
    ("0 1500; 1 1500; 2 1500; 3 1500", r"^sec\.tab: 4 rows; at most 3$"),
])
def test_parse_table_errors_name_row_and_column(text, message):
    with pytest.raises(ModelError, match=message):
        parse_table(text, TABLE, "sec.tab")


def test_parse_table_without_the_increasing_rule():
    free = Table(columns=TABLE.columns, max_rows=3)
    np.testing.assert_array_equal(parse_table("5 1500; 5 1500; 1 1450", free, "w"),
                                  [[5, 1500], [5, 1500], [1, 1450]])


def test_table_parameters_and_values():
    names = [v.name for v in TABLE.array_variables()]
    assert names == ["t[1]", "t[2]", "t[3]", "c[1]", "c[2]", "c[3]"]
    assert all(v.in_table and v.type == "Real" for v in TABLE.array_variables())
    # unused entries start at the allowed value nearest zero
    assert [v.start for v in TABLE.array_variables()] == [0.0] * 3 + [1400.0] * 3
    assert Column("neg", "m", max=-2.0).start == -2.0
    rows = np.array([[1.0, 1450.0], [2.5, 1460.0]])
    values = TABLE.values(rows, "n")
    assert values == {"n": 2, "t[1]": 1.0, "t[2]": 2.5, "c[1]": 1450.0, "c[2]": 1460.0}
    np.testing.assert_array_equal(TABLE.rows(values, "n"), rows)


# ----------------------------------------------------------------------------
# Parameter vectors of a component
# ----------------------------------------------------------------------------

class Toy(Component):
    """A small declaration set whose parameter vector is worked out by hand."""

    name = "toy"

    @classmethod
    def variables(cls, n_beacons: int = 4):
        return (
            Variable("gain", "parameter", "Real", 1.5, "m", min=0.0, max=10.0),
            Variable("mode", "parameter", "String", "y", choices=("x", "y", "z")),
            Variable("path", "parameter", "String", "", scope="config"),
            Variable("rows", "parameter", "Integer", 0, table=TABLE, min=0, max=3, scope="fmu"),
            Variable("on", "parameter", "Boolean", True),
            Variable("count", "parameter", "Integer", 4, min=0, max=9),
            Variable("out", "output", "Real", 0.0, "m"),
        )


def test_parameter_vector_in_declaration_order():
    assert [v.name for v in Toy.fmu_parameters_declared()] == [
        "gain", "mode", "rows", "t[1]", "t[2]", "t[3]", "c[1]", "c[2]", "c[3]", "on", "count"]
    # starts: gain 1.5, mode 'y' -> 1, no rows, unused entries at 0 and 1400, on -> 1, count 4
    np.testing.assert_array_equal(Toy.parameter_vector({}),
                                  [1.5, 1, 0, 0, 0, 0, 1400, 1400, 1400, 1, 4])
    given = dict(gain=2.0, mode="z", on=False, count=7, **TABLE.values(np.array([[1.0, 1450.0], [3.0, 1410.0]]),
                                                                      "rows"))
    np.testing.assert_array_equal(Toy.parameter_vector(given),
                                  [2.0, 2, 2, 1.0, 3.0, 0, 1450.0, 1410.0, 1400, 0, 7])
    with pytest.raises(ModelError, match=r"^toy\.path: not a parameter of the toy FMU"):
        Toy.parameter_vector({"path": "a.csv"})  # a configuration-only key
    with pytest.raises(ModelError, match=r"^toy\.count: 10 is outside the allowed range \[0, 9\]"):
        Toy.parameter_vector({"count": 10})
    with pytest.raises(ModelError, match=r"^toy\.mode: 'w' is not allowed"):
        Toy.parameter_vector({"mode": "w"})


def test_parameter_matrix_takes_per_replicate_arrays():
    matrix = Toy.parameter_matrix({"gain": np.array([0.5, 2.0, 9.0]), "mode": np.array(["z", "x", "z"]),
                                   "count": 3}, 3)
    assert matrix.shape == (3, 11)
    np.testing.assert_array_equal(matrix[:, 0], [0.5, 2.0, 9.0])
    np.testing.assert_array_equal(matrix[:, 1], [2, 0, 2])
    np.testing.assert_array_equal(matrix[:, 10], [3, 3, 3])
    np.testing.assert_array_equal(matrix[:, 2:10], np.tile([0, 0, 0, 0, 1400, 1400, 1400, 1], (3, 1)))
    # a batch of one value per row equals the single vectors
    for b, (g, m) in enumerate(((0.5, "z"), (2.0, "x"), (9.0, "z"))):
        np.testing.assert_array_equal(matrix[b], Toy.parameter_vector({"gain": g, "mode": m, "count": 3}))


@pytest.mark.parametrize("values,message", [
    ({"gain": np.array([1.0, 2.0])}, r"^toy\.gain: 2 per-replicate values for a batch of 3$"),
    ({"gain": np.array([1.0, 2.0, 3.0, 4.0])}, r"^toy\.gain: 4 per-replicate values for a batch of 3$"),
    ({"gain": np.array([1.0, 2.0, 11.0])}, r"^toy\.gain: 11\.0 is outside the allowed range \[0, 10\] m$"),
    ({"count": np.array([1, 2.5, 3])}, r"^toy\.count: expected a whole number"),
    ({"mode": np.array(["x", "y", "w"])}, r"^toy\.mode: 'w' is not allowed"),
    ({"nope": np.array([1.0, 2.0, 3.0])}, r"^toy\.nope: not a parameter"),
])
def test_parameter_matrix_refuses_wrong_arrays(values, message):
    with pytest.raises(ModelError, match=message):
        Toy.parameter_matrix(values, 3)


def test_component_parameter_vectors_of_the_real_models():
    """The platform's choice travels as its index; the target's waypoint text as its table entries."""
    declared = [v.name for v in Platform.fmu_parameters_declared()]
    p = Platform.parameter_vector({"gps_model": "gauss-markov", "baseline": 2.5})
    assert p[declared.index("gps_model")] == 1.0 and p[declared.index("baseline")] == 2.5
    assert p[declared.index("layout")] == 0.0
    with pytest.raises(ModelError, match=r"^platform\.baseline: 0\.0 is outside the allowed range \(0, 1000\] m"):
        Platform.parameter_vector({"baseline": 0.0})
    rows = np.array([[0.0, 1.0, 2.0, 3.0], [4.0, 5.0, 6.0, 7.0]])
    values = Target.fmu_parameters(resolve_parameters(Target.config_parameters(), dict(
        trajectory="file", waypoints=format_table(rows)), "target"))
    q = Target.parameter_vector(values)
    declared = [v.name for v in Target.fmu_parameters_declared()]
    assert q[declared.index("waypoint_rows")] == 2
    for j, col in enumerate(WAYPOINTS.columns):
        np.testing.assert_array_equal([q[declared.index(f"{col.name}[{k}]")] for k in (1, 2)], rows[:, j])
    choices = next(v for v in Target.fmu_parameters_declared() if v.name == "trajectory").choices
    assert q[declared.index("trajectory")] == choices.index("file")


def test_a_whole_number_beyond_double_precision_is_a_range_error():
    with pytest.raises(ModelError, match=r"is outside the allowed range \[0, 8\]"):
        INTEGER.coerce(2**53 + 1, "k")
