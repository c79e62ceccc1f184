"""The FMI 3.0 variables of a component: its FMI 2.0 scalars, grouped into arrays where FMI 3.0 has them.

One table, written from the same declarations as the FMI 2.0 one
(:meth:`sblsim.models.component.Component.fmu_variables`): every FMI 3.0
variable is a scalar of the FMI 2.0 FMU under the same name, or an array whose
elements (row-major) are FMI 2.0 scalars of one causality, variability, type
and unit, named after them (docs/interop.md, "FMI 3.0"):

==============================================  =====================================  ==========
FMI 2.0 scalars                                 FMI 3.0 array                          shape
==============================================  =====================================  ==========
``beacon<k>_x``, ``_y``, ``_z``                 ``beacon_positions``                   [N, 3]
``beacon<k>_true_x``, ``_y``, ``_z``            ``beacon_true_positions``              [N, 3]
``beacon<k>_offset_x``, ``_y``, ``_z``          ``beacon_offsets``                     [N, 3]
``<name>_x``, ``<name>_y``, ``<name>_z``        ``<name>`` (``est``, ``pos``, ``gps``)  [3]
``<name>_vx``, ``<name>_vy``, ``<name>_vz``     ``<name>_v`` (``est_v``, ``x0_v``)      [3]
``cov_xx`` … ``cov_zz`` (upper triangle)        ``cov`` (symmetric, both triangles)    [3, 3]
``lane2_<field>`` … ``lane8_<field>``           ``lanes_<field>`` (lanes 2 … 8)        [7]
a table column ``<column>[1]`` … ``[R]``        ``<column>``                           [R]
==============================================  =====================================  ==========

N is the structural parameter ``n_beacons`` (fixed: the beacon count is compiled in); every other scalar keeps
its FMI 2.0 name. The C shell reads the same table (:func:`fmi3_table_source`), so a value set or got through
an array lands on the same storage as its FMI 2.0 scalar and the numbers are the FMI 2.0 FMU's, bit for bit.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from itertools import count, takewhile
from typing import Sequence

#: FMI 2.0 type -> FMI 3.0 type.
FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
#: The structural parameter of the beacon count.
N_BEACONS = "n_beacons"
#: The outputs by which a model delivers a packet at its arrival (the channel, models/acoustics): its counter and
#: its arrival epoch. An FMI 3.0 FMU with both may return early from doStep at an arrival.
ARRIVAL_OUTPUTS = ("packet_seq", "rx_time")
_BEACON = re.compile(r"^beacon(\d+)_(true_|offset_)?([xyz])$")
_BEACON_ARRAYS = {None: "beacon_positions", "true_": "beacon_true_positions", "offset_": "beacon_offsets"}
_AXES = ("x", "y", "z")
_COV = ("xx", "xy", "xz", "xy", "yy", "yz", "xz", "yz", "zz")


@dataclass(frozen=True)
class Fmi3Variable:
    """One FMI 3.0 variable.

    Attributes
    ----------
    name : str
    causality : str
        ``parameter``, ``input``, ``output`` or ``structuralParameter``.
    variability : str
    fmi_type : str
        ``Float64``, ``Int32``, ``Boolean`` or ``UInt64`` (the structural parameter).
    shape : tuple of int
        ``()`` for a scalar.
    elements : tuple of int
        The FMI 2.0 value references of its elements, row-major (empty for the structural parameter).
    beacon_rows : bool
        Its first dimension is the beacon count (``n_beacons``).
    """

    name: str
    causality: str
    variability: str
    fmi_type: str
    shape: tuple[int, ...]
    elements: tuple[int, ...]
    beacon_rows: bool = False

    @property
    def size(self) -> int:
        """Number of values."""
        n = 1
        for d in self.shape:
            n *= d
        return n


def fmi3_variables(variables: Sequence, n_beacons: int) -> list[Fmi3Variable]:
    """The FMI 3.0 variables of a component, value reference = position in the list.

    Parameters
    ----------
    variables : sequence of sblsim.models.declarations.Variable
        The FMI 2.0 variables (value reference = position): ``model.fmu_variables(n_beacons)``.
    n_beacons : int
        The beacon count compiled into the FMU.

    Returns
    -------
    list of Fmi3Variable
        ``n_beacons`` first when a beacon array is present, then the variables in the order of their first
        FMI 2.0 element.

    Raises
    ------
    ValueError
        If an array would join scalars of different causality, variability, type, unit or range (a
        declaration this grouping does not know).
    """
    vr = {v.name: k for k, v in enumerate(variables)}
    group_of: dict[int, tuple[str, tuple[int, ...], tuple[int, ...], bool]] = {}

    def claim(name: str, members: list[str], shape: tuple[int, ...], beacon_rows: bool = False) -> None:
        elements = tuple(vr[m] for m in members)
        if any(e in group_of for e in elements):
            return
        for e in set(elements):
            group_of[e] = (name, shape, elements, beacon_rows)

    for v in variables:  # table columns
        if v.in_table and v.name.endswith("[1]"):
            column = v.name[:-3]
            rows = list(takewhile(vr.__contains__, (f"{column}[{r}]" for r in count(1))))
            claim(column, rows, (len(rows),))
    families: dict[str | None, dict[tuple[int, str], str]] = {}
    for v in variables:  # beacon<k>_[true_|offset_]<axis>
        match = _BEACON.match(v.name)
        if match and not v.in_table:
            families.setdefault(match.group(2), {})[(int(match.group(1)), match.group(3))] = v.name
    for middle, members in families.items():
        wanted = [(k, a) for k in range(1, n_beacons + 1) for a in _AXES]
        if set(members) == set(wanted):
            claim(_BEACON_ARRAYS[middle], [members[key] for key in wanted], (n_beacons, 3), True)
    for v in variables:  # lane<m>_<field>, m = 2 … : the later lanes of a delivery
        if v.name.startswith("lane2_"):
            field = v.name[len("lane2_"):]
            members = list(takewhile(vr.__contains__, (f"lane{m}_{field}" for m in count(2))))
            claim(f"lanes_{field}", members, (len(members),))
    for v in variables:  # <name>_x/_y/_z and <name>_vx/_vy/_vz
        for suffix, array in (("_x", ""), ("_vx", "_v")):
            if v.name.endswith(suffix):
                base = v.name[: -len(suffix)]
                members = [f"{base}{suffix[:-1]}{a}" for a in _AXES]
                if all(m in vr for m in members) and f"{base}{array}" not in vr:
                    claim(f"{base}{array}", members, (3,))
    if all(f"cov_{c}" in vr for c in _COV):
        claim("cov", [f"cov_{c}" for c in _COV], (3, 3))

    out: list[Fmi3Variable] = []
    if any(g[3] for g in group_of.values()):
        out.append(Fmi3Variable(N_BEACONS, "structuralParameter", "fixed", "UInt64", (), ()))
    done: set[str] = set()
    for k, v in enumerate(variables):
        if k not in group_of:
            out.append(Fmi3Variable(v.name, v.causality, v.variability, FMI3_TYPES[v.fmi_type], (), (k,)))
            continue
        name, shape, elements, beacon_rows = group_of[k]
        if name in done:
            continue
        done.add(name)
        _check_alike(name, [variables[e] for e in elements])
        out.append(Fmi3Variable(name, v.causality, v.variability, FMI3_TYPES[v.fmi_type], shape, elements,
                                beacon_rows))
    names = [v.name for v in out]
    if len(set(names)) != len(names):
        raise ValueError(f"FMI 3.0 variables: a name is used twice ({sorted(n for n in names if names.count(n) > 1)})")
    return out


def element_positions(variables: Sequence[Fmi3Variable]) -> dict[int, tuple[int, int]]:
    """Where each FMI 2.0 variable is among the FMI 3.0 ones: its value reference -> (the FMI 3.0 value reference
    of the variable it is an element of, its first position among that variable's values)."""
    where: dict[int, tuple[int, int]] = {}
    for vr, v in enumerate(variables):
        for k, e in enumerate(v.elements):
            where.setdefault(e, (vr, k))
    return where


def _check_alike(name: str, members: Sequence) -> None:
    first = members[0]
    for m in members[1:]:
        for field in ("causality", "variability", "fmi_type", "unit", "min", "max"):
            if getattr(m, field) != getattr(first, field):
                raise ValueError(f"FMI 3.0 array {name}: {m.name} and {first.name} differ in {field}")


def arrival_outputs(outputs: Sequence) -> tuple[int, int]:
    """The positions among a model's outputs of :data:`ARRIVAL_OUTPUTS`, or (-1, -1) when it has not both."""
    names = [v.name for v in outputs]
    if all(n in names for n in ARRIVAL_OUTPUTS):
        return names.index(ARRIVAL_OUTPUTS[0]), names.index(ARRIVAL_OUTPUTS[1])
    return -1, -1


def fmi3_table_source(variables: Sequence[Fmi3Variable], symbol: str, n_beacons: int,
                      arrival: tuple[int, int] = (-1, -1)) -> str:
    """The C source of the FMI 3.0 variable table (``sblsim_fmi3.h``) the FMI 3.0 shell reads.

    Parameters
    ----------
    variables : sequence of Fmi3Variable
        :func:`fmi3_variables`.
    symbol : str
        The table's C name (``-DSBLSIM_FMI3_TABLE=<symbol>``).
    n_beacons : int
        The value of the structural parameter.
    arrival : (int, int)
        :func:`arrival_outputs` of the model.
    """
    types = {"Float64": "SBLSIM_REAL", "Int32": "SBLSIM_INTEGER", "Boolean": "SBLSIM_BOOLEAN",
             "UInt64": "SBLSIM_UINT64"}
    causalities = {"parameter": "SBLSIM_PARAMETER", "input": "SBLSIM_INPUT", "output": "SBLSIM_OUTPUT",
                   "structuralParameter": "SBLSIM_STRUCTURAL"}
    flat: list[str] = []
    rows = []
    for vr, v in enumerate(variables):
        rows.append(f'{{.name = "{v.name}", .vr = {vr}, .type = {types[v.fmi_type]}, '
                    f".causality = {causalities[v.causality]}, .n_elements = {len(v.elements)}, "
                    f".elements = elements + {len(flat)}, "
                    f".constant = {n_beacons if v.causality == 'structuralParameter' else 0}ULL}}")
        flat += [str(e) for e in v.elements]
    return "\n".join([
        "/* Generated by sblsim (fmus/arrays.py): the FMI 3.0 variables and their FMI 2.0 elements. */",
        '#include "sblsim_fmi3.h"', "",
        "static const int elements[] = {" + (", ".join(flat) or "0") + "};",
        "static const sblsim_fmi3_variable variables[] = {\n    " + ",\n    ".join(rows) + "\n};",
        f"const sblsim_fmi3_table {symbol} = {{.variables = variables, .n_variables = {len(variables)}, "
        f".arrival_seq = {arrival[0]}, .arrival_time = {arrival[1]}}};", ""])


__all__ = ["ARRIVAL_OUTPUTS", "FMI3_TYPES", "Fmi3Variable", "N_BEACONS", "arrival_outputs", "element_positions",
           "fmi3_table_source", "fmi3_variables"]
