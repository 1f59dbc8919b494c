"""``read_recording``: a legacy recording, its reader chosen by the file's extension, as a
:class:`~millwatch.ingest.legacy.recording.Recording` of a mill's channels.

:data:`FORMATS` lists what each format must hold (the README's table and ``millwatch archive
import --help`` show the same). Values are taken as calibrated engineering units.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.legacy.csv_file import read_csv
from millwatch.ingest.legacy.h5_file import read_h5
from millwatch.ingest.legacy.mat_file import read_mat
from millwatch.ingest.legacy.mf4_file import read_mf4
from millwatch.ingest.legacy.recording import Recording, assign_channels, build
from millwatch.ingest.legacy.tdms_file import read_tdms
from millwatch.ingest.legacy.tracks import LegacyFileError, SourceTrack

__all__ = ["FORMATS", "Format", "read_recording", "read_tracks"]


@dataclass(frozen=True)
class Format:
    """A file format: its extensions, what a file must hold, the library that reads it."""

    extensions: tuple[str, ...]
    holds: str
    library: str


#: The formats by name, in the order the help lists them.
FORMATS = {
    "csv": Format(
        (".csv",),
        "header line; column 'time' (s since 1970-01-01 UTC), one column per signal",
        "(none)",
    ),
    "mat": Format(
        (".mat",),
        "one row vector per signal, 'fs' (Hz), 't0' (s since 1970-01-01 UTC, or --start)",
        "scipy",
    ),
    "tdms": Format(
        (".tdms",),
        "group 'Measurement', a channel per signal with wf_increment, wf_start_time, "
        "wf_start_offset",
        "npTDMS",
    ),
    "mf4": Format(
        (".mf4", ".mdf"),
        "MDF 4.10, a signal per channel, relative time stamps, the header's start time (UTC)",
        "asammdf",
    ),
    "h5": Format(
        (".h5", ".hdf5"),
        "a 1-D dataset per signal at the root, attributes 'fs' and 't0' (dataset or root; "
        "or --start)",
        "h5py",
    ),
}


def read_tracks(
    path: Path, *, start_ns: int | None = None, advance: Callable[[int], None] | None = None
) -> list[SourceTrack]:
    """The signals of ``path`` as the file names them (:class:`SourceTrack`\\ s). ``start_ns``:
    the first sample's time (ns since the epoch, UTC) for a file without one, replacing the
    file's own; not for CSV, whose times are absolute. ``advance`` (bytes read): CSV only."""
    if not path.is_file():
        raise LegacyFileError(f"{path}: no such file")
    kind = _kind(path)
    if kind == "csv":
        if start_ns is not None:
            raise LegacyFileError(f"{path}: a CSV file's 'time' column is absolute; --start "
                                  "does not apply to it")  # fmt: skip
        return read_csv(path, advance)
    readers = {"mat": read_mat, "tdms": read_tdms, "mf4": read_mf4, "h5": read_h5}
    return readers[kind](path, start_ns)


def _kind(path: Path) -> str:
    suffix = path.suffix.lower()
    for name, fmt in FORMATS.items():
        if suffix in fmt.extensions:
            return name
    known = ", ".join(e for f in FORMATS.values() for e in f.extensions)
    raise LegacyFileError(f"{path}: unknown format {suffix or '(no extension)'!r}; known: {known}")


def read_recording(
    path: str | Path,
    config: MillConfig,
    mapping: Mapping[str, str] | None = None,
    *,
    ignore: Iterable[str] = (),
    allow_missing: bool = False,
    start_ns: int | None = None,
    advance: Callable[[int], None] | None = None,
) -> Recording:
    """The recording ``path`` as ``config``'s channels on its sample grid: signals named like
    the mill file's ``[channels.<name>]``, or by ``mapping`` ``{signal: channel}``; ``ignore``:
    signals to leave out; ``allow_missing``: import without channels the file lacks
    (:mod:`millwatch.ingest.legacy.recording`). Raises :class:`LegacyFileError` naming what
    is wrong."""
    path = Path(path)
    tracks = read_tracks(path, start_ns=start_ns, advance=advance)
    names = [t.name for t in tracks]
    doubled = sorted({n for n in names if names.count(n) > 1})
    if doubled:
        raise LegacyFileError(
            f"{path}: signal name(s) {', '.join(doubled)} appear more than "
            "once (e.g. in two channel groups): rename them in the file"
        )
    channels = assign_channels(str(path), names, config, mapping, ignore, allow_missing)
    return build(str(path), tracks, config, channels)
