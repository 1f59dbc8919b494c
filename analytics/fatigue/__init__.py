"""Fatigue: rainflow counting and what is kept of its cycles.

The counter and its fact::

    rainflow         RainflowCounter: continual ASTM E1049-85 rainflow, exact across blocks
    residue_modes    how a residue is closed: half (ASTM) or repeat (the record followed by itself)
    repeat_closure   RepeatClosure: the standard repeat closure of a streamed record
    cycles           Cycles: the fact it emits (ranges, means, counts, sample indices)

Recorders (consume Cycles; combine freely, as pyLife's detectors and recorders do)::

    miner            MinerSum, DamageRecorder: Palmgren-Miner damage on one S-N curve, exact
    matrices         RangeMeanMatrix, FromToMatrix: cycle histograms with configured bins
    record_count     RecordCount: a whole record in large chunks — cycles, exact damage, totals
    cycle_log        CycleLog: a whole record's range–mean matrix per trace, and on request
                     every cycle (unbounded: offline analyses only)

Curves and sums::

    sn_curves        SNCurve (m1, m2, S_D, N_D, N_L; scatter sd_log10_N, life_factor), Goodman
                     correction, equivalent range
    sn_models        named S-N models → curves
    exact_sum        correctly rounded sums (compensated, for a year of 1 kHz data); ExactSum
    *_kernels        compiled loops of rainflow, damage, the exact sum and matrix binning

Damage by operating phase (a recorder that also needs the operating states) lives one room up,
in :mod:`millwatch.analytics.mill.phase_damage`, so that fatigue and operation import nothing of
each other.

Data flow: stress samples → RainflowCounter → Cycles → recorders. A new question about cycles
is a new recorder here (keep the Stateful contract: split anywhere, snapshot/restore, bounded
bins from configuration), not a change to the counter or its kernels.
"""
