import math

import numpy as np
import pytest

from mani_skill_space.domains import DOMAINS, blackbody_rgb, get_domain, sample_sun_direction


def test_domain_table_matches_the_reference_figures():
    expected = {"moon": (1.62496, 1361), "mars": (3.72076, 729), "orbit": (0.0, 1361), "earth": (9.80665, 775), "asteroid": (0.14219, 190)}
    assert set(DOMAINS) == set(expected)
    for name, (gravity, sun) in expected.items():
        assert DOMAINS[name].gravity == gravity
        assert DOMAINS[name].sun_irradiance == sun
        assert DOMAINS[name].gravity_vector == [0.0, 0.0, -gravity]


def test_ground_per_domain():
    assert DOMAINS["orbit"].terrain is None and DOMAINS["orbit"].ground_texture is None and not DOMAINS["orbit"].has_ground
    assert all(DOMAINS[name].has_ground for name in ("moon", "mars", "earth", "asteroid"))
    assert DOMAINS["earth"].terrain is None and DOMAINS["earth"].ground_texture == "earth_soil"
    for name in ("moon", "mars", "asteroid"):
        assert DOMAINS[name].terrain is not None and DOMAINS[name].ground_texture == DOMAINS[name].terrain.texture


def test_sky_per_domain():
    assert DOMAINS["moon"].sky == DOMAINS["asteroid"].sky == "stars"
    assert DOMAINS["mars"].sky == "mars_day"
    assert DOMAINS["earth"].sky == "earth_day"
    assert DOMAINS["orbit"].sky == "orbit_earth_limb"


def test_dimmer_sunlight_gives_a_dimmer_sun_light():
    brightness = {name: float(np.max(d.sun_color)) for name, d in DOMAINS.items()}
    assert brightness["moon"] == brightness["orbit"] > brightness["earth"] > brightness["mars"] > brightness["asteroid"] > 0
    for d in DOMAINS.values():
        assert np.max(d.ambient_color) < np.max(d.sun_color)


def test_unknown_or_unsupported_domain_names_the_valid_choices():
    with pytest.raises(ValueError, match="moon, mars, orbit, earth, asteroid"):
        get_domain("venus")
    with pytest.raises(ValueError, match="valid choices: moon, mars$"):
        get_domain("orbit", supported=("moon", "mars"))


def test_sun_direction_stays_within_the_reference_ranges():
    rng = np.random.default_rng(0)
    for _ in range(500):
        d = sample_sun_direction(rng)
        assert math.isclose(np.linalg.norm(d), 1.0)
        elevation = math.degrees(math.asin(-d[2]))
        assert elevation >= 90 - 75 * math.sqrt(2) - 1e-6  # combined roll and pitch tilt
        assert d[2] < 0


def test_blackbody_colour_warms_as_temperature_drops():
    warm, neutral, cool = blackbody_rgb(3000), blackbody_rgb(6500), blackbody_rgb(10000)
    assert warm[0] == 1 and warm[2] < 0.5
    assert np.all(neutral > 0.9)
    assert cool[2] == 1 and cool[0] < 1


def test_a_domain_with_ground_needs_its_texture():
    import dataclasses

    with pytest.raises(ValueError, match="ground texture"):
        dataclasses.replace(DOMAINS["orbit"], has_ground=True)
    with pytest.raises(ValueError, match="ground texture"):
        dataclasses.replace(DOMAINS["moon"], has_ground=False)
