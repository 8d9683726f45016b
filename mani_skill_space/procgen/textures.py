"""Procedural image textures: equirectangular skies for the skydome and tileable ground base colours.

Everything is pure numpy/scipy and deterministic in ``seed`` (only ``np.random.default_rng(seed)`` is used).

Sky UV convention (equirectangular, for a sphere seen from inside): column ``u`` in ``[0, width)`` maps to
azimuth ``2 * pi * (u + 0.5) / width`` and row ``v`` in ``[0, height)`` maps to polar angle
``pi * (v + 0.5) / height``, so row 0 is the zenith, the boundary between rows ``height // 2 - 1`` and
``height // 2`` is the horizon and the last row is the nadir. Skies are meant to be emissive: the pixel
colours are what the camera sees. Internally a pixel's view direction is ``(sin p cos a, sin p sin a, cos p)``
(z up); features that are not rotationally symmetric are sampled from 3-D noise at that direction so they do
not pinch at the poles or break at the azimuth seam.

Ground textures are square base-colour images that tile seamlessly (every noise field is periodic on the
image torus), meant to repeat about once per metre on the terrain mesh.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

SKY_KINDS = ("stars", "mars_day", "earth_day", "orbit_earth_limb")
GROUND_KINDS = ("lunar_regolith", "martian_regolith", "asteroid_rubble", "earth_soil")

NOISE_VOLUME_SIZE = 64
"""Edge of the periodic 3-D noise volume sampled by the skies (voxels)."""
SPHERE_NOISE_RADIUS = 28.0
"""Largest radius (voxels) of the sphere of directions inside the noise volume: under half the period, so no
feature repeats across the sky."""
HORIZON_BLEND_ROWS = 4.0
EARTH_RADIUS_KM = 6371.0
ORBIT_ALTITUDE_KM = 400.0
REFERENCE_SKY_PIXELS = 1024 * 512
"""Star counts are given for this resolution and scaled with the pixel count."""


# ----------------------------------------------------------------------------------------------------------------
# Generic helpers


def _rgb(*values: float) -> np.ndarray:
    return np.array(values, dtype=np.float32)


def _smoothstep(edge0: float, edge1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _mix(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Per-pixel blend of colours (or images) ``a`` and ``b``; ``t`` has the image shape without channels."""
    t = np.asarray(t, dtype=np.float32)[..., None]
    return a * (1.0 - t) + b * t


def _to_uint8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _spectral_noise(rng: np.random.Generator, shape: tuple[int, ...], slope: float,
                    stretch: tuple[float, ...] | None = None) -> np.ndarray:
    """Zero-mean, unit-std noise that is periodic along every axis (FFT-filtered white noise).

    The amplitude falls off as ``frequency ** -slope`` (larger = smoother). ``stretch`` scales each axis'
    frequencies before the fall-off: a factor below 1 keeps finer detail along that axis (streaks across it).
    """
    white = rng.standard_normal(shape, dtype=np.float32)
    axes_freqs = [np.fft.fftfreq(n, 1.0 / n) for n in shape[:-1]] + [np.fft.rfftfreq(shape[-1], 1.0 / shape[-1])]
    stretch = stretch or (1.0,) * len(shape)
    grids = np.meshgrid(*[f * s for f, s in zip(axes_freqs, stretch)], indexing="ij", sparse=True)
    cycles = np.sqrt(sum(g * g for g in grids))
    cycles.flat[0] = 1.0
    amplitude = cycles ** -slope
    amplitude.flat[0] = 0.0
    field = np.fft.irfftn(np.fft.rfftn(white) * amplitude, s=shape).astype(np.float32)
    field -= field.mean()
    return field / max(float(field.std()), 1e-12)


def _sample_periodic_volume(volume: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Trilinear lookup of a periodic volume at ``points`` (..., 3) given in voxel units."""
    coords = points.reshape(-1, 3).T
    values = ndimage.map_coordinates(volume, coords, order=1, mode="grid-wrap")
    return values.reshape(points.shape[:-1])


# ----------------------------------------------------------------------------------------------------------------
# Sky helpers


def _sky_directions(width: int, height: int) -> np.ndarray:
    """Unit view direction (height, width, 3) of every pixel centre, z up."""
    polar = ((np.arange(height, dtype=np.float32) + 0.5) * (np.pi / height))[:, None]
    azimuth = ((np.arange(width, dtype=np.float32) + 0.5) * (2.0 * np.pi / width))[None, :]
    x, y, z = np.broadcast_arrays(np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar))
    return np.stack([x, y, z], axis=-1)


def _sphere_noise(rng: np.random.Generator, directions: np.ndarray, slope: float,
                  radius: float = SPHERE_NOISE_RADIUS) -> np.ndarray:
    """Seamless noise on the sphere of directions, from a fresh periodic volume.

    ``radius`` (voxels, at most ``SPHERE_NOISE_RADIUS``) sets the feature size: smaller = larger features.
    """
    volume = _spectral_noise(rng, (NOISE_VOLUME_SIZE,) * 3, slope)
    offset = rng.uniform(0.0, NOISE_VOLUME_SIZE, 3).astype(np.float32)
    return _sample_periodic_volume(volume, directions * radius + offset)


def _below_horizon_weight(height: int) -> np.ndarray:
    """0 above the horizon, 1 below it, over a few rows centred exactly on the horizon; shape (height, 1)."""
    rows_below = np.arange(height, dtype=np.float32) + 0.5 - height / 2.0
    return _smoothstep(-HORIZON_BLEND_ROWS / 2.0, HORIZON_BLEND_ROWS / 2.0, rows_below)[:, None]


def _random_directions(rng: np.random.Generator, count: int) -> np.ndarray:
    """``count`` directions uniformly distributed on the sphere, shape (count, 3)."""
    z = rng.uniform(-1.0, 1.0, count)
    azimuth = rng.uniform(0.0, 2.0 * np.pi, count)
    ring = np.sqrt(1.0 - z * z)
    return np.stack([ring * np.cos(azimuth), ring * np.sin(azimuth), z], axis=-1)


def _random_star_colours(rng: np.random.Generator, count: int) -> np.ndarray:
    """Star colours (count, 3) in 0..255: mostly dim white, a few bright ones slightly tinted."""
    brightness = 35.0 + 220.0 * rng.uniform(0.0, 1.0, count) ** 7
    tints = np.array([[0.80, 0.86, 1.00], [1.00, 1.00, 1.00], [1.00, 0.94, 0.80], [1.00, 0.82, 0.66]])
    tint = tints[rng.integers(0, len(tints), count)]
    tint_strength = _smoothstep(120.0, 230.0, brightness)[:, None]
    colour = (1.0 - tint_strength) + tint_strength * tint
    return brightness[:, None] * colour / colour.max(axis=1, keepdims=True)


def _draw_stars(image: np.ndarray, directions: np.ndarray, colours: np.ndarray) -> None:
    """Draw point stars in place (brightest wins); bright ones are 2x2 pixels.

    Star widths in pixels grow as 1 / sin(polar angle): equirectangular columns converge near the poles,
    so this keeps stars the same angular size everywhere on the dome.
    """
    height, width = image.shape[:2]
    polar = np.arccos(np.clip(directions[:, 2], -1.0, 1.0))
    azimuth = np.mod(np.arctan2(directions[:, 1], directions[:, 0]), 2.0 * np.pi)
    row = np.minimum((polar / np.pi * height).astype(int), height - 1)
    col = (azimuth / (2.0 * np.pi) * width).astype(int) % width
    side = np.where(colours.max(axis=1) > 180.0, 2, 1)
    span = np.clip(np.ceil(side / np.maximum(np.sin(polar), 1e-3)), 1, 32).astype(int)

    rows, cols, star_colours = [], [], []
    for dr in (0, 1):
        has_row = side > dr
        repeat = span[has_row]
        star = np.repeat(np.flatnonzero(has_row), repeat)
        col_offset = np.arange(len(star)) - np.repeat(np.cumsum(repeat) - repeat, repeat)
        rows.append(np.minimum(row[star] + dr, height - 1))
        cols.append((col[star] + col_offset) % width)
        star_colours.append(colours[star])
    flat_index = np.concatenate(rows) * width + np.concatenate(cols)
    np.maximum.at(image.reshape(-1, 3), flat_index, np.concatenate(star_colours).astype(image.dtype))


def _star_count(width: int, height: int, per_reference_sky: int) -> int:
    return max(1, int(round(per_reference_sky * width * height / REFERENCE_SKY_PIXELS)))


def _starry_space(rng: np.random.Generator, width: int, height: int, directions: np.ndarray) -> np.ndarray:
    """Black sky with stars and a faint Milky Way band along a random tilted great circle, (H, W, 3) float."""
    tilt = rng.uniform(np.radians(35.0), np.radians(75.0))
    heading = rng.uniform(0.0, 2.0 * np.pi)
    band_normal = np.array([np.sin(tilt) * np.cos(heading), np.sin(tilt) * np.sin(heading), np.cos(tilt)])
    band_width = 0.13

    band = np.exp(-0.5 * (directions @ band_normal.astype(np.float32) / band_width) ** 2)
    mottling = np.clip(0.55 + 0.45 * _sphere_noise(rng, directions, slope=1.1), 0.0, 1.5)
    image = band[..., None] * mottling[..., None] * _rgb(20.0, 19.0, 24.0)

    field_stars = _random_directions(rng, _star_count(width, height, 4000))
    candidates = _random_directions(rng, _star_count(width, height, 6000))
    # Keep each candidate with probability equal to the band profile at its direction.
    accept_distance = band_width * np.sqrt(-2.0 * np.log(rng.uniform(size=len(candidates))))
    band_stars = candidates[np.abs(candidates @ band_normal) < accept_distance]
    band_colours = _random_star_colours(rng, len(band_stars)) * 0.6
    _draw_stars(image, np.concatenate([field_stars, band_stars]),
                np.concatenate([_random_star_colours(rng, len(field_stars)), band_colours]))
    return image


# ----------------------------------------------------------------------------------------------------------------
# Skies


def _stars_sky(rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    directions = _sky_directions(width, height)
    space = _starry_space(rng, width, height, directions)
    ground_tone = 80.0 * (1.0 + 0.06 * _sphere_noise(rng, directions, slope=1.2))
    ground = ground_tone[..., None] * _rgb(1.0, 0.985, 0.96)
    return _mix(space, ground, _below_horizon_weight(height))


def _mars_day_sky(rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    directions = _sky_directions(width, height)
    elevation = np.arcsin(np.clip(directions[..., 2], -1.0, 1.0))
    height_above = np.clip(np.sin(elevation), 0.0, 1.0)
    horizon_colour, zenith_colour = _rgb(234.0, 188.0, 136.0), _rgb(178.0, 122.0, 80.0)
    sky = _mix(horizon_colour, zenith_colour, height_above ** 0.55)
    haze = _sphere_noise(rng, directions, slope=1.6, radius=10.0)
    sky *= (1.0 + 0.045 * haze)[..., None]

    regolith_tone = 1.0 + 0.08 * _sphere_noise(rng, directions, slope=1.3)
    ground = regolith_tone[..., None] * _rgb(140.0, 80.0, 50.0)
    depression = np.degrees(np.maximum(-elevation, 0.0))
    dust = 0.55 * np.exp(-depression / 2.0)
    ground = _mix(ground, horizon_colour * 0.92, dust)
    return _mix(sky, ground, _below_horizon_weight(height))


def _earth_day_sky(rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    directions = _sky_directions(width, height)
    elevation = np.degrees(np.arcsin(np.clip(directions[..., 2], -1.0, 1.0)))
    height_above = np.clip(directions[..., 2], 0.0, 1.0)
    horizon_colour, zenith_colour = _rgb(188.0, 210.0, 232.0), _rgb(38.0, 92.0, 190.0)
    sky = _mix(horizon_colour, zenith_colour, height_above ** 0.45)

    cloud_band = _smoothstep(4.0, 18.0, elevation) * (1.0 - _smoothstep(50.0, 78.0, elevation))
    cloud_noise = _sphere_noise(rng, directions, slope=1.45, radius=20.0)
    cover = _smoothstep(0.3, 1.1, cloud_noise + 0.6 * cloud_band - 0.6) * cloud_band
    shadow = _smoothstep(-1.0, 1.5, _sphere_noise(rng, directions, slope=1.2, radius=12.0))
    cloud_colour = _mix(_rgb(250.0, 250.0, 252.0), _rgb(200.0, 204.0, 214.0), shadow)
    sky = _mix(sky, cloud_colour, 0.95 * cover)

    soil_tone = _sphere_noise(rng, directions, slope=1.2)
    ground = _mix(_rgb(78.0, 96.0, 52.0), _rgb(112.0, 94.0, 64.0), _smoothstep(-1.0, 1.0, soil_tone))
    depression = np.maximum(-elevation, 0.0)
    ground = _mix(ground, horizon_colour * 0.85, 0.6 * np.exp(-depression / 1.5))
    return _mix(sky, ground, _below_horizon_weight(height))


def _earth_surface_colour(rng: np.random.Generator, surface_km: np.ndarray, nadir_point: np.ndarray) -> np.ndarray:
    """Day-side albedo colour (N, 3) of Earth surface points given in km from Earth's centre (N, 3)."""
    land_volume = _spectral_noise(rng, (NOISE_VOLUME_SIZE,) * 3, slope=1.5)
    cloud_volume = _spectral_noise(rng, (NOISE_VOLUME_SIZE,) * 3, slope=1.25)
    offsets = rng.uniform(0.0, NOISE_VOLUME_SIZE, (5, 3)).astype(np.float32)

    def sample(volume: np.ndarray, km_per_voxel: float, offset: np.ndarray) -> np.ndarray:
        return _sample_periodic_volume(volume, surface_km / km_per_voxel + offset)

    # The station is kept over ocean (as for most of an orbit) so the view straight down is mostly sea.
    nadir_distance = np.linalg.norm(surface_km - nadir_point, axis=-1)
    land_height = sample(land_volume, 80.0, offsets[0]) - 2.2 * np.exp(-((nadir_distance / 500.0) ** 2))
    land = _smoothstep(0.12, 0.24, land_height)
    vegetation = _smoothstep(-0.4, 0.6, sample(land_volume, 35.0, offsets[1]))
    land_colour = _mix(_rgb(165.0, 135.0, 90.0), _rgb(62.0, 92.0, 45.0), vegetation)
    ocean_colour = _mix(_rgb(8.0, 30.0, 85.0), _rgb(20.0, 75.0, 130.0), _smoothstep(0.0, 0.3, land_height))
    colour = _mix(ocean_colour, land_colour, land)

    cloud_density = (sample(cloud_volume, 110.0, offsets[2]) + 0.5 * sample(cloud_volume, 25.0, offsets[3])
                     + 0.25 * sample(cloud_volume, 6.0, offsets[4]))
    cover = _smoothstep(0.45, 0.95, cloud_density)
    return _mix(colour, _rgb(238.0, 240.0, 245.0), cover)


def _orbit_earth_limb_sky(rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    directions = _sky_directions(width, height)
    space = _starry_space(rng, width, height, directions)

    orbit_radius = EARTH_RADIUS_KM + ORBIT_ALTITUDE_KM
    toward_up = orbit_radius * directions[..., 2]
    closest_approach_sq = orbit_radius**2 - np.minimum(toward_up, 0.0) ** 2
    hits_earth = (toward_up < 0.0) & (closest_approach_sq < EARTH_RADIUS_KM**2)

    # Atmospheric glow above the limb, by the ray's tangent altitude (scale heights exaggerated to stay visible).
    tangent_altitude = np.sqrt(closest_approach_sq) - EARTH_RADIUS_KM
    altitude = np.maximum(tangent_altitude, 0.0)
    inner_glow = np.exp(-altitude / 15.0)
    outer_glow = np.exp(-altitude / 50.0)
    glow = (outer_glow[..., None] * _rgb(25.0, 75.0, 220.0) + inner_glow[..., None] * _rgb(160.0, 180.0, 35.0))
    image = space * (1.0 - np.minimum(outer_glow * 1.5, 1.0))[..., None] + glow

    hit_directions = directions[hits_earth]
    camera = np.array([0.0, 0.0, orbit_radius], dtype=np.float32)
    along = orbit_radius * hit_directions[:, 2]
    distance = -along - np.sqrt(np.maximum(along**2 - orbit_radius**2 + EARTH_RADIUS_KM**2, 0.0))
    surface_km = camera + distance[:, None] * hit_directions
    albedo = _earth_surface_colour(rng, surface_km, np.array([0.0, 0.0, EARTH_RADIUS_KM], dtype=np.float32))

    # Aerial perspective: the view path through the air grows as the ray grazes the surface near the limb.
    cos_incidence = np.maximum(-np.sum(hit_directions * surface_km, axis=-1) / EARTH_RADIUS_KM, 0.0)
    transmittance = np.exp(-0.16 / np.maximum(cos_incidence, 0.02))[:, None]
    haze_colour = _rgb(125.0, 175.0, 245.0)
    image[hits_earth] = albedo * transmittance + haze_colour * (1.0 - transmittance)
    return image


# ----------------------------------------------------------------------------------------------------------------
# Ground helpers


def _pixel_grid(size: int) -> np.ndarray:
    """Pixel-centre coordinates (size * size, 2) as (x, y)."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) + 0.5
    return np.stack([x.ravel(), y.ravel()], axis=-1)


def _stamp_pebbles(rng: np.random.Generator, size: int, count: int,
                   radius_range: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Soft discs at random places, wrapping around the edges: (coverage in 0..1, relief in about -1..1).

    ``relief`` is brighter on the upper-left half of each pebble, giving a hint of roundness.
    """
    centres = rng.uniform(0.0, size, (count, 2)).astype(np.float32)
    radii = rng.uniform(*radius_range, count).astype(np.float32)
    reach = int(np.ceil(radius_range[1] + 1.0))
    dy, dx = np.mgrid[-reach:reach + 1, -reach:reach + 1]
    px = np.floor(centres[:, 0])[:, None, None] + dx
    py = np.floor(centres[:, 1])[:, None, None] + dy
    offset_x = px + 0.5 - centres[:, 0, None, None]
    offset_y = py + 0.5 - centres[:, 1, None, None]
    distance = np.hypot(offset_x, offset_y)
    coverage = np.clip(radii[:, None, None] + 0.5 - distance, 0.0, 1.0)
    relief = coverage * np.clip(-(offset_x + offset_y) / (radii[:, None, None] * 1.414), -1.0, 1.0)

    flat_index = (py.astype(int) % size) * size + (px.astype(int) % size)
    coverage_map = np.zeros(size * size, dtype=np.float32)
    relief_map = np.zeros(size * size, dtype=np.float32)
    np.maximum.at(coverage_map, flat_index.ravel(), coverage.ravel())
    np.add.at(relief_map, flat_index.ravel(), relief.ravel())
    return coverage_map.reshape(size, size), np.clip(relief_map, -1.0, 1.0).reshape(size, size)


def _speckles(rng: np.random.Generator, size: int, fraction: float) -> np.ndarray:
    """Single-pixel random mask (size, size) with about ``fraction`` of the pixels set, as 0/1 floats."""
    return (rng.uniform(size=(size, size)) < fraction).astype(np.float32)


def _periodic_voronoi(rng: np.random.Generator, size: int, cell_count: int) -> tuple[np.ndarray, ...]:
    """Voronoi cells on the torus: (cell id, distance to own centre, gap to the next centre, dx, dy).

    dx, dy are the pixel's offset from its cell centre, all maps (size, size).
    """
    centres = rng.uniform(0.0, size, (cell_count, 2))
    pixels = _pixel_grid(size)
    distances, cells = cKDTree(centres, boxsize=size).query(pixels, k=2)
    offset = np.mod(pixels - centres[cells[:, 0]] + size / 2.0, size) - size / 2.0
    maps = (cells[:, 0], distances[:, 0], distances[:, 1] - distances[:, 0], offset[:, 0], offset[:, 1])
    return tuple(m.reshape(size, size) for m in maps)


# ----------------------------------------------------------------------------------------------------------------
# Grounds


def _lunar_regolith(rng: np.random.Generator, size: int) -> np.ndarray:
    tone = (0.07 * _spectral_noise(rng, (size, size), slope=1.2)
            + 0.05 * _spectral_noise(rng, (size, size), slope=0.3))
    coverage, relief = _stamp_pebbles(rng, size, count=max(1, size * size // 350),
                                      radius_range=(0.004 * size, 0.014 * size))
    shade = 1.0 + tone - 0.3 * coverage + 0.08 * relief
    shade -= 0.25 * _speckles(rng, size, 0.015)
    shade += 0.45 * _speckles(rng, size, 0.004)
    return shade[..., None] * _rgb(120.0, 118.0, 114.0)


def _martian_regolith(rng: np.random.Generator, size: int) -> np.ndarray:
    hue = _smoothstep(-1.5, 1.5, _spectral_noise(rng, (size, size), slope=1.6))
    base = _mix(_rgb(175.0, 98.0, 58.0), _rgb(150.0, 92.0, 64.0), hue)
    tone = (0.08 * _spectral_noise(rng, (size, size), slope=1.3)
            + 0.05 * _spectral_noise(rng, (size, size), slope=0.3))
    coverage, relief = _stamp_pebbles(rng, size, count=max(1, size * size // 300),
                                      radius_range=(0.004 * size, 0.018 * size))
    image = base * (1.0 + tone)[..., None]
    pebble_colour = _rgb(95.0, 62.0, 48.0) * (1.0 + 0.2 * relief)[..., None]
    image = _mix(image, pebble_colour, 0.85 * coverage)
    return image * (1.0 - 0.2 * _speckles(rng, size, 0.012))[..., None]


def _asteroid_rubble(rng: np.random.Generator, size: int) -> np.ndarray:
    shade = np.ones((size, size), dtype=np.float32)
    for cell_count, weight in ((max(4, size * size // 2600), 0.8), (max(8, size * size // 330), 0.6)):
        cell, distance, gap, dx, dy = _periodic_voronoi(rng, size, cell_count)
        cell_radius = np.sqrt(size * size / (np.pi * cell_count))
        cell_tone = rng.uniform(-0.18, 0.18, cell_count)[cell]
        roundness = -0.2 * np.minimum(distance / cell_radius, 1.1) ** 2 - 0.1 * (dx + dy) / cell_radius
        crack = 1.0 - _smoothstep(0.0, 0.09 * cell_radius, gap)
        shade += weight * (cell_tone + roundness - 0.35 * crack)
    shade += 0.06 * _spectral_noise(rng, (size, size), slope=0.4)
    shade = 1.0 + (shade - shade.mean())
    return shade[..., None] * _rgb(70.0, 68.0, 65.0)


def _earth_soil(rng: np.random.Generator, size: int) -> np.ndarray:
    grass_amount = _smoothstep(-0.6, 0.6, _spectral_noise(rng, (size, size), slope=1.5) + 0.2)
    blades = _spectral_noise(rng, (size, size), slope=0.6, stretch=(0.25, 1.0))
    grass = _mix(_rgb(62.0, 92.0, 36.0), _rgb(112.0, 128.0, 52.0), _smoothstep(-1.8, 1.8, blades))
    soil_tone = (0.08 * _spectral_noise(rng, (size, size), slope=1.2)
                 + 0.06 * _spectral_noise(rng, (size, size), slope=0.3))
    soil = _rgb(112.0, 86.0, 60.0) * (1.0 + soil_tone)[..., None]
    coverage, relief = _stamp_pebbles(rng, size, count=max(1, size * size // 900),
                                      radius_range=(0.004 * size, 0.012 * size))
    soil = _mix(soil, _rgb(135.0, 125.0, 112.0) * (1.0 + 0.2 * relief)[..., None], 0.8 * coverage)
    return _mix(soil, grass, grass_amount * _smoothstep(-1.2, 0.4, blades + grass_amount))


# ----------------------------------------------------------------------------------------------------------------
# Public API

_SKY_GENERATORS: dict[str, Callable[[np.random.Generator, int, int], np.ndarray]] = {
    "stars": _stars_sky,
    "mars_day": _mars_day_sky,
    "earth_day": _earth_day_sky,
    "orbit_earth_limb": _orbit_earth_limb_sky,
}
_GROUND_GENERATORS: dict[str, Callable[[np.random.Generator, int], np.ndarray]] = {
    "lunar_regolith": _lunar_regolith,
    "martian_regolith": _martian_regolith,
    "asteroid_rubble": _asteroid_rubble,
    "earth_soil": _earth_soil,
}
assert tuple(_SKY_GENERATORS) == SKY_KINDS and tuple(_GROUND_GENERATORS) == GROUND_KINDS


def make_sky_texture(kind: str, width: int = 1024, height: int = 512, seed: int = 0) -> np.ndarray:
    """Equirectangular sky texture, uint8 (height, width, 3); see the module docstring for the UV convention."""
    if kind not in _SKY_GENERATORS:
        raise ValueError(f"Unknown sky kind {kind!r}; valid kinds: {', '.join(SKY_KINDS)}")
    return _to_uint8(_SKY_GENERATORS[kind](np.random.default_rng(seed), width, height))


def make_ground_texture(kind: str, size: int = 256, seed: int = 0) -> np.ndarray:
    """Seamlessly tileable ground base-colour texture, uint8 (size, size, 3)."""
    if kind not in _GROUND_GENERATORS:
        raise ValueError(f"Unknown ground kind {kind!r}; valid kinds: {', '.join(GROUND_KINDS)}")
    return _to_uint8(_GROUND_GENERATORS[kind](np.random.default_rng(seed), size))
