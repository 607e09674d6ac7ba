"""The one unit table of pendulab's FMUs and SSP files: each unit's SI base-unit exponents and display units.

``modelDescription.xml`` (FMI 2.0 and 3.0) and the SSP's ``<ssd:Units>`` are written from :data:`UNITS`, so
a tool can check that two connected variables have the same dimension and convert between units (N.s/m and
kg/s are the same dimension: the table says so). Angles are shown in degrees (``DisplayUnit`` deg).

Examples
--------
>>> UNITS["N.s/m"] == UNITS["kg/s"]
True
>>> base_unit_attributes("V")
'kg="1" m="2" s="-3" A="-1"'
>>> display_unit("rad/s")
'deg/s'
"""

from __future__ import annotations

import math
from typing import Mapping

#: SI base units in the order of FMI's ``<BaseUnit>`` attributes (rad is FMI's own, for angles).
BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def _u(**exponents: int) -> dict[str, int]:
    return {k: exponents[k] for k in BASE_UNITS if exponents.get(k)}


#: Unit name (as the variable tables write it) -> exponents of the SI base units.
UNITS: dict[str, dict[str, int]] = {
    "1": _u(),
    "m/m": _u(),
    "s": _u(s=1),
    "m": _u(m=1),
    "m/s": _u(m=1, s=-1),
    "m/s2": _u(m=1, s=-2),
    "rad": _u(rad=1),
    "rad/s": _u(rad=1, s=-1),
    "rad/s2": _u(rad=1, s=-2),
    "kg": _u(kg=1),
    "kg/s": _u(kg=1, s=-1),
    "kg.m2": _u(kg=1, m=2),
    "N": _u(kg=1, m=1, s=-2),
    "N.s/m": _u(kg=1, s=-1),
    "N.m.s/rad": _u(kg=1, m=2, s=-1, rad=-1),
    "N.m/A": _u(kg=1, m=2, s=-2, A=-1),
    "A": _u(A=1),
    "V": _u(kg=1, m=2, s=-3, A=-1),
    "V/m": _u(kg=1, m=1, s=-3, A=-1),
    "V/rad": _u(kg=1, m=2, s=-3, A=-1, rad=-1),
    "V.s/rad": _u(kg=1, m=2, s=-2, A=-1, rad=-1),
    "V.s/m": _u(kg=1, m=1, s=-2, A=-1),
    "Ohm": _u(kg=1, m=2, s=-3, A=-2),
}

#: Unit -> its display units: name -> factor (display value = factor * value).
DISPLAY_UNITS: dict[str, dict[str, float]] = {
    "rad": {"deg": 180 / math.pi},
    "rad/s": {"deg/s": 180 / math.pi},
    "rad/s2": {"deg/s2": 180 / math.pi},
}


def check_unit(unit: str, where: str) -> None:
    """Raise ``ValueError`` naming ``where`` if ``unit`` is not in :data:`UNITS` (add it there)."""
    if unit and unit not in UNITS:
        raise ValueError(f"{where}: unit {unit!r} is not in pendulab.fmu.units.UNITS; add its SI exponents there")


def base_unit_attributes(unit: str) -> str:
    """The ``<BaseUnit>`` attributes of ``unit`` (nothing for a dimensionless unit)."""
    return " ".join(f'{k}="{v}"' for k, v in UNITS[unit].items())


def display_unit(unit: str) -> str | None:
    """The display unit a variable of ``unit`` is shown in by default (degrees for angles), or None."""
    return next(iter(DISPLAY_UNITS.get(unit, {})), None)


def unit_definitions(units: Mapping[str, object] | list[str], indent: str, prefix: str = "") -> list[str]:
    """``<Unit>`` elements (with ``<BaseUnit>`` and ``<DisplayUnit>``) for ``units``; ``prefix`` is an XML
    namespace prefix (``"ssc:"`` in SSP), the same element names in FMI 2.0, FMI 3.0 and SSP 1.0."""
    lines = []
    for unit in sorted(units):
        check_unit(unit, "unit definitions")
        lines.append(f'{indent}<{prefix}Unit name="{unit}">')
        lines.append(f"{indent}  <{prefix}BaseUnit {base_unit_attributes(unit)}/>".replace(" />", "/>"))
        if not prefix:  # SSP units carry no display units
            for name, factor in DISPLAY_UNITS.get(unit, {}).items():
                lines.append(f'{indent}  <DisplayUnit name="{name}" factor="{factor!r}"/>')
        lines.append(f"{indent}</{prefix}Unit>")
    return lines
