"""What the mill is doing: operating states and the measures of each phase.

Modules::

    operating_states OperatingStateMachine: stopped/starting/running/stopping/barring/unknown
                     from speed and torque, one Transition per change (Diering 2011 §6.1)
    transients       start, stop and barring measures on one phase's samples (Diering 2011 §6.2)
    runup            the torsional resonance crossed on a run-up (Diering 2011 §6.1.1): short-time
                     spectra of the start's torque, the burst's frequency and speed, the model's
                     nearest natural frequency (Fedin & Vinogradov 2018)
    steady_state     SteadyStateMeter: steady windows of running (mean, oscillation, imbalance)
    state_kernels, steady_kernels   their compiled loops

Data flow: speed + torque → state machine (a counter emitting transitions) → the load stage
cuts phases from them, measures closed phases with ``transients`` (a start also with
``runup``) and feeds running samples to
the steady-state meter. A new event measure goes in ``transients``; a new per-window metric in
``steady_state``; a new state needs the state machine and its kernel.
"""
