"""Reading mill configuration files (TOML) from disk.

The model and its validation live in :mod:`millwatch.analytics.drivetrain.mill_config` (pure); this
module adds the file
reading and turns every failure into a
:class:`~millwatch.analytics.drivetrain.mill_config.MillConfigError` whose message
names the file and each bad field, e.g.::

    deploy/mills/sag1.toml: drive.reducer_ratio: must be > 0
"""

from __future__ import annotations

import logging
import tomllib
from pathlib import Path

from pydantic import ValidationError

from millwatch.analytics.drivetrain.mill_config import (
    MillConfig,
    MillConfigError,
    describe_validation_error,
)

__all__ = ["MillConfigError", "load_mill_config", "load_mill_configs"]

log = logging.getLogger(__name__)


def load_mill_config(path: str | Path) -> MillConfig:
    """Read and validate one mill TOML file.

    Raises :class:`MillConfigError` (a ``ValueError``) naming the file and the bad fields, for
    unreadable files, TOML syntax errors and validation errors alike.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise MillConfigError(str(path), [f"cannot read: {exc}"]) from exc
    try:
        config = MillConfig.from_toml_text(text)
    except tomllib.TOMLDecodeError as exc:
        raise MillConfigError(str(path), [f"TOML syntax error: {exc}"]) from exc
    except ValidationError as exc:
        raise MillConfigError(str(path), describe_validation_error(exc)) from exc
    log.debug("loaded mill %s/%s from %s", config.site, config.id, path)
    return config


def load_mill_configs(directory: str | Path) -> dict[str, MillConfig]:
    """Load every ``*.toml`` in ``directory`` (sorted by name), keyed by mill id.

    Raises :class:`MillConfigError` for the first bad file or for a mill id used twice.
    """
    mills: dict[str, MillConfig] = {}
    origin: dict[str, Path] = {}
    for path in sorted(Path(directory).glob("*.toml")):
        config = load_mill_config(path)
        if config.id in mills:
            raise MillConfigError(
                str(path), [f"id: {config.id!r} already used by {origin[config.id]}"]
            )
        mills[config.id] = config
        origin[config.id] = path
    return mills
