import numpy as np
import pytest
import trimesh

from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.procgen.asset import GPU_CONVEX_VERTEX_LIMIT
from mani_skill_space.procgen.debris import (
    BUS_SIZE,
    DEBRIS_KINDS,
    FRAGMENT_DENSITY,
    SATELLITE_DENSITY,
    make_debris,
    make_fragment,
    make_satellite,
)

SEEDS = range(12)
PANDA_OPENING = 0.08


def test_every_kind_of_debris_comes_up():
    kinds = {make_debris(seed).info["kind"] for seed in range(40)}
    assert kinds == {"satellite", "fragment", "rock"} and set(DEBRIS_KINDS) == {"satellite", "fragment", "rock"}


@pytest.mark.parametrize("seed", SEEDS)
def test_solid_is_watertight_and_centred_on_its_centre_of_mass(seed):
    debris = make_debris(seed)
    solid = debris.solid if debris.solid is not None else debris.visual_mesh
    assert solid.is_watertight and solid.is_volume
    np.testing.assert_allclose(solid.center_mass, 0.0, atol=1e-6)


@pytest.mark.parametrize("seed", SEEDS)
def test_collision_parts_are_convex_cookable_and_make_up_the_solid(seed):
    debris = make_debris(seed)
    for part in debris.collision_parts:
        assert part.mesh.is_convex and len(part.mesh.vertices) <= GPU_CONVEX_VERTEX_LIMIT
    if debris.solid is not None:  # the parts overlap a little where they join; their union is the solid
        union = trimesh.boolean.union([p.mesh for p in debris.collision_parts], engine="manifold")
        np.testing.assert_allclose(union.volume, debris.solid.volume, rtol=1e-6)


def test_mass_and_inertia_follow_the_solid_and_its_density():
    satellite = next(make_satellite(seed) for seed in range(20) if len(make_satellite(seed).collision_parts) > 3)
    mass, centre, inertia = satellite.mass_properties()
    assert mass == pytest.approx(satellite.solid.volume * SATELLITE_DENSITY)
    # the overlapping parts would count the joints twice
    assert mass < sum(p.mesh.volume for p in satellite.collision_parts) * SATELLITE_DENSITY
    np.testing.assert_allclose(centre, 0.0, atol=1e-6)
    assert np.all(np.linalg.eigvalsh(inertia) > 0)
    fragment = make_fragment(3)
    assert fragment.mass_properties()[0] == pytest.approx(fragment.visual_mesh.volume * FRAGMENT_DENSITY)


@pytest.mark.parametrize("seed", SEEDS)
def test_satellite_bus_fits_between_the_open_fingers_whichever_way_it_turns(seed):
    bus = np.asarray(make_satellite(seed).info["bus_size"])
    assert np.all((BUS_SIZE[0] <= bus) & (bus <= BUS_SIZE[1]))
    assert np.linalg.norm(bus) < PANDA_OPENING


def test_same_seed_same_debris_and_different_seeds_differ():
    a, b, c = make_debris(5), make_debris(5), make_debris(6)
    assert a.name == b.name
    for x, y in zip(a.collision_parts, b.collision_parts):
        np.testing.assert_array_equal(x.mesh.vertices, y.mesh.vertices)
    assert a.name != c.name or not np.array_equal(a.visual_mesh.vertices, c.visual_mesh.vertices)


@pytest.mark.parametrize("name, size", [("cubesat_1u", (0.04, 0.04, 0.0454)), ("cubesat_3u", (0.04, 0.04, 0.1362))])
def test_dataset_cubesats_are_40_percent_scale_and_fit_the_gripper_across(name, size):
    cubesat = load_dataset_object(name)
    np.testing.assert_allclose(np.sort(cubesat.solid.extents), np.sort(size), atol=1e-4)
    assert np.hypot(size[0], size[1]) < PANDA_OPENING  # across its square section, whichever way it rolls
    assert cubesat.mass_properties()[0] == pytest.approx(cubesat.solid.volume * 1330.0)
