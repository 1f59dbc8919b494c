"""The per-mill composition: MillAnalyzer, and the stages only it combines.

One analyzer object per mill, used alike by live ingest, replay and offline analysis
(README "Design": identical results for the same samples).

Modules (each imports only the ones listed before it)::

    results          typed results as they leave the analyzer (start/stop/barring events, a
                     steady-state window, a component's damage), read by attribute by every
                     surface
    cycle_matrix     CycleMatrixDays: rainflow range-mean matrices of a component's counted
                     cycles per local day and phase (stress after the stress factors, MPa;
                     edges from the mill file's full scales), their sparse stored form
    phase_damage     PhaseTimeline, PhaseDamage: the damage and cycle recorder by operating phase
                     and local day, the phase-sum cost of a start (life's what-if), the one
                     SECONDS_PER_YEAR of damage rates (Diering 2011 §8.3, App. D); the
                     cycles' range-mean matrices (cycle_matrix); here
                     because it joins fatigue (cycles, Miner) with operation (states)
    report           the tables of the load report (starts per month, phase seconds, damage,
                     start cost, projections), from plain pieces
    load_roles       LoadRoles: which mill-file channels are the speed, each side's motor
                     torque, pinion torque and bending (the ring's rows), the damage
                     components; steady_channels, component_names
    load_days        StreamClock (stream sample → time, local day), PhaseDays: phase samples
                     in total and per local day, cut at the site's midnights
    load_events      EventBook: start/stop/barring events measured as their phases close
                     (Diering 2011 §6.1.1, §6.2.3, §6.2.5), starts per day/month/total;
                     keep (a bounded list of plain JSON records)
    load_steady      SteadyProgress: decided running samples → the steady-state meter → windows
    load_damage      FatigueCounting: stress per component (Diering 2011 §8.1–8.2, App. D §3),
                     the NaN hold, rainflow counters and damage recorders (each component on its
                     own S-N curve and mean-stress correction; the critical plane's traces)
    load_snapshot    the load stage's checkpoint format (kind, version 3, keys in order) and the
                     renaming of a version-2 checkpoint
    app_d            AppDCounting: the cost of a start as Diering 2011 App. D counts it (start and
                     stop portions joined, residue counted; run portion steady running only),
                     live per start-stop record; AppDCost, app_d_month, app_d_projections
    loads            LoadAnalysis: the load stage — feeds the state machine and the ring, hands
                     frames and transitions to the load_* parts (each owns its state and its
                     keys of the snapshot), the report; snapshot/restore
    analyzer         MillAnalyzer: THE per-mill analyzer — calibration, aligner, faults, tacho,
                     LoadAnalysis, harmonic tracker; its public reading API is what callers use

Data flow: block → MillAnalyzer (calibrate, align, flag, tacho) → LoadAnalysis.feed(frame)
→ events, windows, damage; → HarmonicTracker on the running samples. A new per-mill output
is read through a public method/property on MillAnalyzer (callers never reach into its
stages); a new piece of LoadAnalysis state goes in the ``snapshot``/``load`` of the part that
owns it, and its key in ``load_snapshot.KEYS`` (a test fails otherwise); a new report table is
a function in ``report``. Every per-channel result is keyed by the channel's name in the mill
file (``load_roles.steady_channels``), never by a side index.
"""
