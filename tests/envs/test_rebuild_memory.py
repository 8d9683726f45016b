"""Scene rebuilds on the CPU defer ManiSkill's full garbage collection (``FULL_COLLECTION_EVERY``) without keeping
old scenes alive for longer than that, and closing an env still collects at once (as ManiSkill's ``close`` does)."""

import gc
import weakref

import pytest

from mani_skill_space.envs.base import FULL_COLLECTION_EVERY


@pytest.fixture
def counted_collections(monkeypatch):
    calls = []
    collect = gc.collect

    def counting(*args):
        calls.append(args)
        return collect(*args)

    monkeypatch.setattr(gc, "collect", counting)
    return calls


def test_rebuilds_collect_once_every_few_and_free_the_old_scenes(make_sample_collection, counted_collections):
    env = make_sample_collection(asset_source="procedural")
    env.reset(seed=0)
    counted_collections.clear()
    scenes = []
    for seed in range(1, 3 * FULL_COLLECTION_EVERY + 1):
        env.reset(seed=seed)
        scenes.append(weakref.ref(env.unwrapped.scene))
    assert len(counted_collections) == 3
    alive = [i for i, scene in enumerate(scenes[:-1]) if scene() is not None]
    assert len(alive) < FULL_COLLECTION_EVERY, f"old scenes still alive: {alive}"


def test_close_collects_at_once(make_sample_collection, counted_collections):
    env = make_sample_collection()
    env.reset(seed=0)
    counted_collections.clear()
    env.close()
    assert len(counted_collections) == 1
