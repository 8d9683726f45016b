"""Space domains: one frozen table of physical and visual constants (sim-free).

Figures follow the Space Robotics Bench reference (see SPEC.md): gravity, solar irradiance and sun colour
temperature per domain. The renderer has no physical units: irradiance maps to a directional light
intensity proportional to its square root (a camera's auto-exposure partly compensating dim sunlight, so an
asteroid at 2.7 AU is darker than the Moon but still visible), with 1361 W/m^2 at ``SUN_INTENSITY_AT_1AU``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

SUN_INTENSITY_AT_1AU = 2.4
"""Directional light intensity (renderer units) for 1361 W/m^2 of sunlight."""

SKY_TO_SUN_RATIO = 0.25
"""Reference: the sky (ambient) light is 0.25x the sun."""

SUN_ROLL_RANGE_DEG = (-75.0, 75.0)
SUN_PITCH_RANGE_DEG = (0.0, 75.0)


@dataclass(frozen=True)
class TerrainStyle:
    """Parameters of the procedural ground around the robot (see ``procgen.terrain``)."""

    texture: str
    roughness_amplitude: float
    roughness_wavelength: float
    crater_count: tuple[int, int]
    crater_radius: tuple[float, float]
    dune_amplitude: float = 0.0
    boulder_count: int = 0


@dataclass(frozen=True)
class Domain:
    name: str
    gravity: float
    """Magnitude of the gravitational acceleration in m/s^2 (acting along -z)."""
    sun_irradiance: float
    """Solar irradiance in W/m^2."""
    sun_color_temperature: float
    """Colour temperature of the sunlight in kelvin."""
    sky: str
    """Sky texture kind (``procgen.textures.SKY_KINDS``)."""
    sky_tint: tuple[float, float, float]
    """Colour of the ambient (sky) light."""
    terrain: Optional[TerrainStyle]
    """Procedural terrain; None for plain ground (``ground_texture``) or for no ground at all."""
    ground_texture: Optional[str]
    """Texture of the ground: the terrain's, or that of plain ground; None where there is no ground (orbit)."""
    rock_flavour: str
    """Procedural rock style of this domain (``procgen.rock.ROCK_FLAVOURS``)."""
    has_ground: bool
    """Whether there is a surface to stand on: on a planet or an asteroid the arm rides a rover on the ground;
    in orbit (no ground) it stands on a station's work platform and nothing falls."""

    def __post_init__(self):
        if self.has_ground != (self.ground_texture is not None):
            raise ValueError(f"domain {self.name!r}: a domain with ground needs a ground texture, one without needs none")

    @property
    def gravity_vector(self) -> list[float]:
        return [0.0, 0.0, -self.gravity]

    @property
    def sun_color(self) -> np.ndarray:
        """RGB of the directional sun light: blackbody colour times the irradiance-dependent intensity."""
        intensity = SUN_INTENSITY_AT_1AU * math.sqrt(self.sun_irradiance / 1361.0)
        return blackbody_rgb(self.sun_color_temperature) * intensity

    @property
    def ambient_color(self) -> np.ndarray:
        return np.asarray(self.sky_tint) * float(np.max(self.sun_color)) * SKY_TO_SUN_RATIO


LUNAR_TERRAIN = TerrainStyle(
    texture="lunar_regolith",
    roughness_amplitude=0.05,
    roughness_wavelength=1.2,
    crater_count=(10, 16),
    crater_radius=(0.3, 1.2),
)
MARTIAN_TERRAIN = TerrainStyle(
    texture="martian_regolith",
    roughness_amplitude=0.04,
    roughness_wavelength=1.6,
    crater_count=(2, 4),
    crater_radius=(0.4, 1.0),
    dune_amplitude=0.12,
    boulder_count=12,
)
ASTEROID_TERRAIN = TerrainStyle(
    texture="asteroid_rubble",
    roughness_amplitude=0.08,
    roughness_wavelength=0.6,
    crater_count=(4, 8),
    crater_radius=(0.3, 0.9),
    boulder_count=40,
)

DOMAINS: dict[str, Domain] = {
    d.name: d
    for d in (
        Domain("moon", 1.62496, 1361.0, 5778.0, "stars", (0.55, 0.55, 0.6), LUNAR_TERRAIN, LUNAR_TERRAIN.texture, "lunar", has_ground=True),
        Domain("mars", 3.72076, 729.0, 6250.0, "mars_day", (1.0, 0.78, 0.55), MARTIAN_TERRAIN, MARTIAN_TERRAIN.texture, "martian", has_ground=True),
        Domain("orbit", 0.0, 1361.0, 5778.0, "orbit_earth_limb", (0.55, 0.65, 0.85), None, None, "lunar", has_ground=False),
        Domain("earth", 9.80665, 775.0, 5750.0, "earth_day", (0.75, 0.85, 1.0), None, "earth_soil", "martian", has_ground=True),
        Domain("asteroid", 0.14219, 190.0, 5778.0, "stars", (0.5, 0.5, 0.55), ASTEROID_TERRAIN, ASTEROID_TERRAIN.texture, "lunar", has_ground=True),
    )
}


def get_domain(name: str, supported: tuple[str, ...] | None = None) -> Domain:
    """Look a domain up by name; ``supported`` narrows the valid choices (a task's domains)."""
    valid = tuple(supported) if supported is not None else tuple(DOMAINS)
    if name not in valid:
        raise ValueError(f"Unknown domain {name!r}; valid choices: {', '.join(valid)}")
    return DOMAINS[name]


def blackbody_rgb(temperature_k: float) -> np.ndarray:
    """Normalised RGB of a blackbody (Tanner Helland's fit, 1000-40000 K), brightest channel = 1."""
    t = temperature_k / 100.0
    red = 255.0 if t <= 66 else 329.698727446 * (t - 60) ** -0.1332047592
    green = 99.4708025861 * math.log(t) - 161.1195681661 if t <= 66 else 288.1221695283 * (t - 60) ** -0.0755148492
    if t >= 66:
        blue = 255.0
    elif t <= 19:
        blue = 0.0
    else:
        blue = 138.5177312231 * math.log(t - 10) - 305.0447927307
    rgb = np.clip(np.array([red, green, blue]), 0.0, 255.0)
    return rgb / rgb.max()


def sample_sun_direction(rng: np.random.Generator, pitch_range_deg: tuple[float, float] = SUN_PITCH_RANGE_DEG) -> np.ndarray:
    """Direction the sunlight travels (unit vector, pointing down), from the reference roll/pitch ranges
    (``pitch_range_deg`` replaces the pitch range, e.g. for a held-out sun direction).

    Roll tilts the sun sideways (about x), pitch tilts it forward/back (about y); (0, 0) is straight overhead.
    """
    roll = math.radians(rng.uniform(*SUN_ROLL_RANGE_DEG))
    pitch = math.radians(rng.uniform(*pitch_range_deg))
    direction = np.array([0.0, 0.0, -1.0])
    rot_x = np.array([[1, 0, 0], [0, math.cos(roll), -math.sin(roll)], [0, math.sin(roll), math.cos(roll)]])
    rot_y = np.array([[math.cos(pitch), 0, math.sin(pitch)], [0, 1, 0], [-math.sin(pitch), 0, math.cos(pitch)]])
    return rot_y @ rot_x @ direction
