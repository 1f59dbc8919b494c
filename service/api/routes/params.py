"""The path and query parameters the routes share, each validated one way everywhere.

A route takes ``mill_id: MillId`` or ``alarm_id: AlarmId`` — never a bare ``str`` — so an id the
configuration could not hold is a 422 naming the parameter before any backend is asked.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Path, Query

from millwatch.reports.starts import MONTH_PATTERN

__all__ = ["MILL_ID_PATTERN", "AlarmId", "MillId", "Month", "Site"]

MILL_ID_PATTERN = r"^[a-z0-9][a-z0-9_\-]*$"
"""What a mill's configured ``id`` may be (``MillConfig.id``; a test keeps the two equal)."""

MillId = Annotated[
    str,
    Path(
        pattern=MILL_ID_PATTERN,
        max_length=64,
        description="The mill's id, e.g. sag-5200-lrs.",
    ),
]
Site = Annotated[
    str,
    Path(
        pattern=MILL_ID_PATTERN,
        max_length=64,
        description="The site's id (``site`` of the mill files), e.g. rustenburg.",
    ),
]
AlarmId = Annotated[str, Path(max_length=200, description="The alarm's id.")]
Month = Annotated[
    str | None,
    Query(
        pattern=MONTH_PATTERN,
        description=(
            "YYYY-MM, a calendar month in the site's time zone; default: the mill's current "
            "month, that of its last analysed sample (as status.starts_this_month)."
        ),
        examples=["2024-05"],
    ),
]
