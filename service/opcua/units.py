"""Engineering units of the OPC UA variables: UNECE Rec. 20 codes as OPC UA ``EUInformation``.

OPC UA Part 8 §5.6.3 names the UNECE "Codes for Units of Measure" (Recommendation 20) as the
units namespace: ``UnitId`` is the code's characters packed into an integer (8 bits each), the
namespace URI :data:`UNECE_URI`. A unit of millwatch (the strings its API and mill files use)
maps to one code here; a unit not listed (damage per year) has no ``EngineeringUnits``
property.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["UNECE_URI", "UNITS", "Unit", "unit_id"]

UNECE_URI = "http://www.opcfoundation.org/UA/units/un/cefact"


@dataclass(frozen=True, slots=True)
class Unit:
    """A UNECE unit: ``code`` (Rec. 20), ``symbol`` (the display name), ``description``."""

    code: str
    symbol: str
    description: str


def unit_id(code: str) -> int:
    """The OPC UA ``UnitId`` of a UNECE code (Part 8 §5.6.3: ASCII bytes, big-endian)."""
    value = 0
    for char in code:
        value = (value << 8) | ord(char)
    return value


UNITS: dict[str, Unit] = {
    "kN·m": Unit("B73", "kN·m", "kilonewton metre"),
    "MPa": Unit("MPA", "MPa", "megapascal"),
    "rpm": Unit("RPM", "r/min", "revolutions per minute"),
    "%": Unit("P1", "%", "percent"),
    "s": Unit("SEC", "s", "second"),
    "a": Unit("ANN", "a", "year"),
    "1": Unit("C62", "1", "one (dimensionless)"),
}
"""millwatch unit → UNECE unit."""
