"""How the open residue of a rainflow count is closed: the modes and what each one means.

A light module (no numpy), so that the command line can offer the choices without importing
the counter.

``half`` — ASTM E1049-85 §5.4.4: the ranges the three-point rule leaves open are counted as
half cycles (with those it already counted from the record's start while running). The default
everywhere, and what the live service books.

``repeat`` — the record followed by itself, the standard closure for a record that is one
period of a repeating duty (Amzallag et al., "Standardization of the rainflow counting method for
fatigue analysis", Int. J. Fatigue 16 (1994) 287–293; ISO 12110-2; fatpack's
``find_rainflow_ranges``): the four-point rule over the record, then over its residue joined to
itself at a clean reversal; the full cycles of both passes are the record's cycles, and there are
no half cycles. It equals the count of one period of the repeated signal: on the Lee/Barkey/Kang
handbook history ``[2, -1, 3, -5, 4, -4, 2]`` the full ranges 3, 7 and 9.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["RESIDUE_MODE_HELP", "ResidueMode"]


class ResidueMode(StrEnum):
    """How the open residue is closed (see the module docstring)."""

    HALF = "half"
    REPEAT = "repeat"


#: One line per mode, for ``--help`` texts.
RESIDUE_MODE_HELP = {
    ResidueMode.HALF: "the open ranges as half cycles (ASTM E1049, the default)",
    ResidueMode.REPEAT: (
        "the record followed by itself (four-point rule over the record, then over its residue "
        "joined to itself: full cycles only; the standard closure of a repeating duty)"
    ),
}
