"""Harmonic tracking: order-tracked Welch spectra of steady running, lines measured.

Modules::

    settings         HarmonicSettings (the knobs), stagger_for, is_running (speed-band test)
    tapers           cosine-sum windows and their response off a line (scalloping)
    tracker          HarmonicTracker: the counter; running samples → segments → HarmonicWindow
    segments         WelchSums, SegmentSpectrum, DROP_REASONS, describe_segments (accounting)
    tables           HarmonicTables: averaged segments → measured lines and unexplained peaks
    resonance        resonance_margins: a window's excitations against the torsional natural
                     frequencies (the resonance_margin alarm's value)
    facts            HarmonicWindow, LineMeasurement, UnexplainedPeak (plain, frozen)
    report           harmonics_report: the long-run table of a tracker
    running_median   NoiseFloor, local maxima (the tables' noise floor)
    order_kernels, median_kernels   compiled loops (demodulation, resampling, medians)

Data flow: running samples (torque, bending, speed) → tracker → segments → Welch sums →
tables → HarmonicWindow facts (expected lines from ``drivetrain.kinematics``; unexplained peaks
with the nearest natural frequency of ``drivetrain.torsional_model``) → ``resonance`` margins,
the worker's tables and alarms, and ``report``. A new view of the facts (a trend, a daily
aggregate) is a recorder that consumes HarmonicWindow; a new knob goes in ``settings``.
"""
