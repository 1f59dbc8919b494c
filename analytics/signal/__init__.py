"""From per-channel blocks to aligned, fault-flagged frames at one sample rate.

Modules::

    frame_aligner    FrameAligner: blocks of equal t0 → aligned Frames; gaps as NaN
    fault_stage      FaultStage: every channel of a frame checked, all delayed alike;
                     LastGood: flagged samples held at the last good value, frame to frame
    telemetry_faults TelemetryFaultDetector: spikes, dropouts, zero runs, rail pins per channel
                     (Diering 2011 §5.2.2); hold_last_good
    tacho            TachoSpeed: pulse train → rpm (Diering 2011 App. C routine 5)
    sample_ring      SampleRing: the last seconds of several channels by stream sample
    *_kernels        compiled loops of the aligner, fault detector and tacho

Data flow: calibrated block → FrameAligner → FaultStage (flags, fixed delay) → TachoSpeed
(derived rpm channel) → the load stage. A new per-channel check is a detector here, wired
into FaultStage; its hot loop goes in a ``*_kernels.py`` beside it.
"""
