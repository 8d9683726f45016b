"""The static assets in the package are exactly what ``assets/make_assets.py`` produces."""

import numpy as np
from PIL import Image

from mani_skill_space.assets import make_assets
from mani_skill_space.dataset import asset_root, dataset_object_names, load_dataset_object
from mani_skill_space.domains import DOMAINS
from mani_skill_space.procgen.asset_io import load_asset


def test_shipped_textures_match_the_generator(tmp_path):
    for path in make_assets.write_textures(tmp_path):
        shipped = asset_root() / path.relative_to(tmp_path)
        assert shipped.is_file(), shipped
        np.testing.assert_array_equal(np.asarray(Image.open(shipped)), np.asarray(Image.open(path)))


def test_shipped_dataset_objects_match_the_generator(tmp_path):
    assert set(dataset_object_names()) == set(make_assets.DATASET_OBJECTS)
    for folder in make_assets.write_dataset(tmp_path):
        fresh, shipped = load_asset(folder), load_dataset_object(folder.name)
        for a, b in zip(fresh.visual_parts + fresh.collision_parts, shipped.visual_parts + shipped.collision_parts):
            np.testing.assert_allclose(a.mesh.vertices, b.mesh.vertices, atol=1e-6)
            np.testing.assert_array_equal(a.mesh.faces, b.mesh.faces)


def test_every_domain_has_its_sky_and_ground_textures():
    for domain in DOMAINS.values():
        assert (asset_root() / "sky" / f"{domain.sky}.png").is_file()
        if domain.terrain is not None:
            assert (asset_root() / "textures" / f"{domain.terrain.texture}.png").is_file()


def test_sample_tube_is_33_by_170_mm_and_one_exact_convex_part():
    tube = load_dataset_object("sample_tube")
    np.testing.assert_allclose(tube.visual_mesh.extents, [0.170, 0.033, 0.033], atol=2e-4)
    (part,) = tube.collision_parts
    assert part.mesh.is_convex and len(part.mesh.vertices) <= 64
    np.testing.assert_allclose(part.mesh.volume, tube.visual_mesh.volume, rtol=1e-6)
    np.testing.assert_allclose(tube.visual_mesh.center_mass, 0, atol=1e-6)
