from __future__ import annotations

import pytest

from tests.ingest.legacy.scene_files import SceneData, make_scene, outcome


@pytest.fixture(scope="session")
def scene(tmp_path_factory) -> SceneData:
    return make_scene(tmp_path_factory.mktemp("legacy-scene"))


@pytest.fixture(scope="session")
def scene_outcome(scene):
    """The analysis of the scene's own MCAP (the live recording)."""
    return outcome(scene.mcap, scene.config)
