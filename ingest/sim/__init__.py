"""The scene simulator: synthetic 1 kHz drivetrain telemetry with ground truth.

A *scene* is a mill configuration plus a timeline of operating events (starts, stops, trips,
failed starts, barring sessions) and faults (telemetry spikes, dropouts, an extra torsional
line). The record of a start follows Diering 2011 §6.1.1, Figure 20, with the numbers of its
Tables 3–17. Same seed, same samples — bitwise, whatever the chunk size.

What is here, in the order data flows:

- ``spec``         what a scene is: ``SceneSpec``, ``SceneParams``, the event types
- ``scenes``       the catalogue of named scenes and scene files → ``SceneSpec`` (a mill file's
                   ``[simulation]`` parameters under the scene's own)
- ``seed_tables``  Diering 2011's numbers: peak torques per starter, barring, bending, line weights
- ``waveforms``    signal shapes: raised-cosine fronts, ringing, the steady oscillation lines
- ``segments``     one operating stretch each (idle, start, run, stop, barring) → drivetrain state
- ``timeline``     events → consecutive segments, angle-continuous
- ``faults``       extra lines and channel patches (spikes, NaN dropouts)
- ``truth``        ``SceneTruth``: what was put in (peaks, lines, faults), for tests and benches
- ``renderer``     ``Scene``: composes the above, renders chunks (engineering units), measures truth
- ``blocks``       chunks → wire blocks on the mill's channel keys
- ``publisher``    blocks → zenoh, paced, as a stand-in sensor gateway

Where a new thing goes: a new scene → ``scenes``; a new operating event → ``spec`` (the event),
``segments`` (its shape) and ``timeline`` (when it may happen); a new fault → ``spec`` and
``faults``; a new truth field → ``truth`` and the renderer's measurement of it. Any new random
draw goes after the existing ones of its generator, or every seed's output changes.
"""
