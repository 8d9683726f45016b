import numpy as np
import pytest

from mani_skill_space.procgen.textures import GROUND_KINDS, SKY_KINDS, make_ground_texture, make_sky_texture


@pytest.fixture(scope="module")
def default_skies():
    return {kind: make_sky_texture(kind) for kind in SKY_KINDS}


@pytest.fixture(scope="module")
def default_grounds():
    return {kind: make_ground_texture(kind) for kind in GROUND_KINDS}


def _channel_means(image):
    return image.reshape(-1, 3).astype(np.float64).mean(axis=0)


def _upper_half(image):
    return image[: image.shape[0] // 2]


@pytest.mark.parametrize("kind", SKY_KINDS)
def test_sky_default_shape_and_dtype(default_skies, kind):
    sky = default_skies[kind]
    assert sky.shape == (512, 1024, 3)
    assert sky.dtype == np.uint8


@pytest.mark.parametrize("kind", SKY_KINDS)
@pytest.mark.parametrize("width, height", [(64, 32), (300, 150)])
def test_sky_custom_size(kind, width, height):
    sky = make_sky_texture(kind, width=width, height=height, seed=3)
    assert sky.shape == (height, width, 3)
    assert sky.dtype == np.uint8


@pytest.mark.parametrize("kind", SKY_KINDS)
def test_sky_is_deterministic_in_seed(kind):
    first = make_sky_texture(kind, width=256, height=128, seed=7)
    again = make_sky_texture(kind, width=256, height=128, seed=7)
    other = make_sky_texture(kind, width=256, height=128, seed=8)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)


@pytest.mark.parametrize("kind", SKY_KINDS)
def test_sky_has_no_seam_at_azimuth_wrap(default_skies, kind):
    sky = default_skies[kind].astype(np.float64)
    interior = np.abs(np.diff(sky, axis=1)).mean()
    seam = np.abs(sky[:, 0] - sky[:, -1]).mean()
    assert seam < 2.0 * interior + 1.0


def test_unknown_sky_kind_lists_valid_kinds():
    with pytest.raises(ValueError) as error:
        make_sky_texture("jupiter_clouds")
    assert all(kind in str(error.value) for kind in SKY_KINDS)


def test_stars_sky_is_dark_with_bright_stars_and_grey_ground(default_skies):
    sky = default_skies["stars"]
    upper = _upper_half(sky)
    assert upper.mean() < 20
    assert (upper.max(axis=-1) > 200).sum() >= 10
    assert 60 < sky[-sky.shape[0] // 4 :].mean() < 100


def test_stars_sky_horizon_transition_is_sharp(default_skies):
    sky = default_skies["stars"].astype(np.float64)
    horizon = sky.shape[0] // 2
    rows = sky.mean(axis=(1, 2))
    assert rows[horizon - 4] < 20
    assert rows[horizon + 3] > 60


def test_earth_day_sky_is_blue(default_skies):
    red, _, blue = _channel_means(_upper_half(default_skies["earth_day"]))
    assert blue > red


def test_mars_day_sky_is_butterscotch(default_skies):
    red, green, blue = _channel_means(_upper_half(default_skies["mars_day"]))
    assert red > green > blue


def test_mars_day_sky_is_brighter_near_horizon(default_skies):
    sky = default_skies["mars_day"].astype(np.float64)
    horizon = sky.shape[0] // 2
    assert sky[horizon - 10 : horizon - 2].mean() > sky[:10].mean()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_orbit_sky_shows_dark_space_above_and_blue_earth_below(seed):
    sky = make_sky_texture("orbit_earth_limb", seed=seed)
    height = sky.shape[0]
    red, _, blue = _channel_means(sky[int(0.8 * height) :])
    assert blue > red
    assert sky[: height // 10].mean() < 20


def test_orbit_sky_limb_is_below_horizon(default_skies):
    sky = default_skies["orbit_earth_limb"].astype(np.float64)
    height = sky.shape[0]
    row_brightness = sky.mean(axis=(1, 2))
    limb_row = int(np.argmax(row_brightness > 40))
    assert height // 2 < limb_row < int(0.75 * height)


@pytest.mark.parametrize("kind", GROUND_KINDS)
def test_ground_default_shape_and_dtype(default_grounds, kind):
    ground = default_grounds[kind]
    assert ground.shape == (256, 256, 3)
    assert ground.dtype == np.uint8


@pytest.mark.parametrize("kind", GROUND_KINDS)
@pytest.mark.parametrize("size", [16, 100])
def test_ground_custom_size(kind, size):
    ground = make_ground_texture(kind, size=size, seed=2)
    assert ground.shape == (size, size, 3)
    assert ground.dtype == np.uint8


@pytest.mark.parametrize("kind", GROUND_KINDS)
def test_ground_is_deterministic_in_seed(kind):
    first = make_ground_texture(kind, size=64, seed=11)
    again = make_ground_texture(kind, size=64, seed=11)
    other = make_ground_texture(kind, size=64, seed=12)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)


@pytest.mark.parametrize("kind", GROUND_KINDS)
@pytest.mark.parametrize("seed", [0, 5])
def test_ground_tiles_seamlessly(kind, seed):
    ground = make_ground_texture(kind, seed=seed).astype(np.float64)
    for axis in (0, 1):
        interior = np.abs(np.diff(ground, axis=axis)).mean()
        first, last = np.take(ground, 0, axis=axis), np.take(ground, -1, axis=axis)
        assert np.abs(first - last).mean() < 2.0 * interior


@pytest.mark.parametrize("kind", GROUND_KINDS)
def test_ground_is_not_flat(default_grounds, kind):
    assert default_grounds[kind].astype(np.float64).std(axis=(0, 1)).min() > 3.0


@pytest.mark.parametrize(
    "kind, expected_rgb",
    [
        ("lunar_regolith", (120, 118, 114)),
        ("martian_regolith", (165, 95, 60)),
        ("asteroid_rubble", (70, 68, 65)),
    ],
)
def test_ground_base_colour(default_grounds, kind, expected_rgb):
    np.testing.assert_allclose(_channel_means(default_grounds[kind]), expected_rgb, atol=15)


def test_earth_soil_is_green_brown(default_grounds):
    red, green, blue = _channel_means(default_grounds["earth_soil"])
    assert green > blue and red > blue


def test_unknown_ground_kind_lists_valid_kinds():
    with pytest.raises(ValueError) as error:
        make_ground_texture("snow")
    assert all(kind in str(error.value) for kind in GROUND_KINDS)
