"""The per-mill composition: MillAnalyzer, and the stages only it combines.

One analyzer object per mill, used alike by live ingest, replay and offline analysis
(README "Design": identical results for the same samples).

Modules (each imports only the ones listed before it)::

    results          typed results as they leave the analyzer (start/stop/barring events, a
                     steady-state window, a component's damage), read by attribute by every
                     surface
    phase_damage     PhaseTimeline, PhaseDamage: the damage and cycle recorder by operating phase
                     and local day, the cost of a start, monthly projections, the one
                     SECONDS_PER_YEAR of damage rates (Diering 2011 §8.3, App. D); here
                     because it joins fatigue (cycles, Miner) with operation (states)
    report           the tables of the load report (starts per month, phase seconds, damage,
                     start cost, projections), from plain pieces
    loads            LoadAnalysis: the load stage — states, events, steady state, rainflow and
                     damage per component, phase and day; owns its snapshot/restore
    analyzer         MillAnalyzer: THE per-mill analyzer — calibration, aligner, faults, tacho,
                     LoadAnalysis, harmonic tracker; its public reading API is what callers use

Data flow: block → MillAnalyzer (calibrate, align, flag, tacho) → LoadAnalysis.feed(frame)
→ events, windows, damage; → HarmonicTracker on the running samples. A new per-mill output
is read through a public method/property on MillAnalyzer (callers never reach into its
stages); a new piece of LoadAnalysis state goes in its ``snapshot``/``_load`` (a test fails
otherwise); a new report table is a function in ``report``. Every per-channel result is keyed by
the channel's name in the mill file (``loads.steady_channels``), never by a side index.
"""
