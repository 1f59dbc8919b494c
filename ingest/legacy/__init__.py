"""Legacy recordings in: CSV, Matlab .mat, NI TDMS, ASAM MDF4 and HDF5 files as wire blocks.

An engineer's recordings (calibrated engineering units, one signal per mill channel) become the
blocks a plant gateway would have sent for the same samples, so every offline command
(``analyze``, ``spectrum``, ``archive export``) reads them through the live path unchanged.

Data flow::

    FILE ──<format> reader──▶ SourceTrack per signal (file's names, its own timing)
         ──recording──▶ Recording: mill channels (``--map``), runs on the mill's sample grid
         ──to_mcap──▶ wire blocks (raw = the inverse of the mill file's calibration),
                      sequence numbers on the block grid (a gap = missing blocks) ──▶ MCAP

What is here:

- ``tracks``      ``SourceTrack``, ``LegacyFileError``, start-time parsing, optional readers
- ``recording``   ``Recording`` and ``Run``; signal names → channels; timestamps → the grid
                  (a jump is a gap, anything off the grid an error naming the row)
- ``csv_file``, ``mat_file``, ``tdms_file``, ``mf4_file``, ``h5_file``  one reader per format
- ``read``        ``read_recording(path, config, …)``: the reader by extension, ``FORMATS``
- ``to_mcap``     ``uncalibrate``, ``recording_blocks``, ``write_mcap``

Where a new thing goes: a new format → a ``<format>_file.py`` returning ``SourceTrack``\\ s and
one line in ``read.FORMATS``; its library → the ``formats`` extra in pyproject.toml.
"""
