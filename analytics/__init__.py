"""Pure computation: numpy arrays in, plain data out; no zenoh, HTTP or files.

Pure computation: numpy arrays in, plain data out. No zenoh, no HTTP, no files.

Rooms (lower ones never import higher ones; nothing here imports ``ingest``, ``alarms`` or
``service``)::

    contracts        the Stateful protocol (split-anywhere, snapshot/restore) and check_snapshot
    snapshot_arrays  numpy arrays inside snapshots (base64, exact)
    drivetrain/      the mill config, kinematics (expected lines), stress model, torsional model
    signal/          per-channel blocks → aligned frames; telemetry faults; tacho → rpm
    operation/       operating states, start/stop/barring measures, steady-state windows
    fatigue/         rainflow → cycles → recorders (Miner damage per S-N curve, matrices, phases)
    spectra/         order-tracked harmonic spectra while running
    mill/            the per-mill composition of all of the above (MillAnalyzer)

How samples flow (one :class:`~millwatch.analytics.mill.analyzer.MillAnalyzer` per mill)::

    block → calibration → FrameAligner → FaultStage → tacho → rpm
          → LoadAnalysis: operating states → events (start, stop, barring), steady state,
                          rainflow per component → recorders (damage per S-N curve,
                          matrices, per phase and day)
          → HarmonicTracker (running samples only) → HarmonicWindow facts

Where things go: a counter emits facts; a new question about its facts is a new recorder in
the counter's room (e.g. a new damage view in ``fatigue/``), not a change to a kernel. Compiled
per-sample loops live only in ``*_kernels.py`` modules beside the plain-Python API that calls
them. Every stateful object keeps :class:`millwatch.analytics.contracts.Stateful` and checks
snapshots with
:func:`millwatch.analytics.contracts.check_snapshot`.
"""
