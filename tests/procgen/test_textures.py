import numpy as np
import pytest

from mani_skill_space.procgen.textures import GROUND_KINDS, SKY_KINDS, make_ground_texture, make_sky_texture

W, H = 256, 128


@pytest.mark.parametrize("kind", SKY_KINDS)
def test_sky_shape_dtype_and_determinism(kind):
    a, b, c = make_sky_texture(kind, W, H, seed=1), make_sky_texture(kind, W, H, seed=1), make_sky_texture(kind, W, H, seed=2)
    assert a.shape == (H, W, 3) and a.dtype == np.uint8
    assert np.array_equal(a, b) and not np.array_equal(a, c)


@pytest.mark.parametrize("kind", GROUND_KINDS)
def test_ground_shape_dtype_and_determinism(kind):
    a, b, c = make_ground_texture(kind, 64, seed=1), make_ground_texture(kind, 64, seed=1), make_ground_texture(kind, 64, seed=2)
    assert a.shape == (64, 64, 3) and a.dtype == np.uint8
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_unknown_kinds_name_the_valid_ones():
    with pytest.raises(ValueError, match="stars, mars_day, earth_day, orbit_earth_limb"):
        make_sky_texture("venus_clouds")
    with pytest.raises(ValueError, match="lunar_regolith, martian_regolith, asteroid_rubble, earth_soil"):
        make_ground_texture("snow")


def _upper(image):
    return image[: image.shape[0] // 2].astype(np.float64)


def test_starry_sky_is_black_with_bright_stars():
    upper = _upper(make_sky_texture("stars", 1024, 512))
    assert upper.mean() < 20
    assert upper.max() > 200


def test_earth_sky_is_blue_and_mars_sky_is_butterscotch():
    earth = _upper(make_sky_texture("earth_day", W, H)).reshape(-1, 3).mean(axis=0)
    assert earth[2] > earth[0] + 30
    mars = _upper(make_sky_texture("mars_day", W, H)).reshape(-1, 3).mean(axis=0)
    assert mars[0] > mars[1] > mars[2]


def test_orbit_sky_has_dark_space_above_and_blue_earth_below():
    sky = make_sky_texture("orbit_earth_limb", W, H).astype(np.float64)
    assert sky[: H // 8].mean() < 25
    nadir = sky[-H // 8 :].reshape(-1, 3).mean(axis=0)
    assert nadir[2] > nadir[0] and nadir.mean() > 60


@pytest.mark.parametrize("kind", [k for k in SKY_KINDS if k != "orbit_earth_limb"])
def test_ground_domains_have_ground_coloured_lower_half(kind):
    sky = make_sky_texture(kind, W, H).astype(np.float64)
    lower = sky[H // 2 + 4 :]
    assert lower.mean() > 40  # a lit ground tone, so the horizon beyond the terrain mesh looks continuous


@pytest.mark.parametrize("kind", GROUND_KINDS)
def test_ground_textures_tile_seamlessly(kind):
    image = make_ground_texture(kind, 128).astype(np.float64)
    interior_columns = np.abs(np.diff(image, axis=1)).mean()
    interior_rows = np.abs(np.diff(image, axis=0)).mean()
    assert np.abs(image[:, 0] - image[:, -1]).mean() < 2 * interior_columns
    assert np.abs(image[0] - image[-1]).mean() < 2 * interior_rows
