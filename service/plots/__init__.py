"""Engineering plots of an analysed recording: matplotlib figures from typed results.

Each function takes arrays and the analyzer's typed records and returns a
:class:`matplotlib.figure.Figure` (Agg canvas, no GUI; matplotlib is imported when a figure is
made, never at import time), so a notebook, a report or ``millwatch analyze --plots DIR`` draw
the same picture::

    events      event_figure: a start's or stop's torques and speed against time, its events
                (switch-on, peaks, resonance, steady, stop, rest) marked and labelled
                (Diering 2011 §6.1.1, Figure 20)
    campbell    campbell_figure: short-time spectra of a run-up against speed, the mill's
                excitation orders and the torsional model's natural frequencies drawn, the
                resonance crossed marked (Diering 2011 §6.1.1–6.1.2; Fedin & Vinogradov 2018)
    matrix      matrix_figure: a component's rainflow range–mean matrix (the monthly report's
                panel, :func:`millwatch.reports.figures.matrix_panel`; Fotopoulos 1983 ch. 3)
    trend       trend_figure: the run-up resonance start by start against the model's natural
                frequency and the natural_frequency_shift alarm band
    files       write_plots: all of them for an analysed recording, as PNG files (re-reads the
                recording for the samples of each start and stop; ``analyze --plots DIR``)

Data flow: samples + typed records (:class:`~millwatch.analytics.mill.results.StartEvent`,
:class:`~millwatch.analytics.fatigue.matrices.RangeMeanMatrix`, …) → a figure; the spectra of a
run-up come from :func:`millwatch.analytics.operation.runup.runup_spectrogram`, the computation
the analyzer's resonance search uses. A new plot goes in a module of its own here, taking typed
inputs and returning a Figure; ``files`` writes them for a recording.
"""
