"""Test helper: every sample of a short scene keyed by zenoh key, the oracle for what a simulated
recording or a simulated live mill must carry."""

from __future__ import annotations

import numpy as np

from millwatch.ingest import keys
from millwatch.ingest.sim.renderer import Scene


def channel_samples(scene: Scene) -> dict[str, np.ndarray]:
    """Every sample of every channel of a (short) scene, keyed by zenoh key: for tests."""
    config = scene.config
    data = scene.render(0, scene.n_samples)
    return {
        keys.channel_key(config.site, config.id, ch.key): data[name]
        for name, ch in config.channels.items()
    }
