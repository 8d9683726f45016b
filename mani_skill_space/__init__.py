"""mani-skill-space: space robotics manipulation tasks for ManiSkill3.

Importing the package registers every env id (``SampleCollection-v1``, ...) with ManiSkill and gymnasium.
The sim-free subpackages (``procgen``, ``domains``, ``rewards``) also import where ManiSkill is not
installed; then there is nothing to register.
"""

import importlib.util

__version__ = "0.1.0"

if importlib.util.find_spec("mani_skill") is not None:
    from mani_skill_space.envs import TASKS  # registers the envs

    ENV_IDS = tuple(TASKS)
    """Every env id this package registers."""
else:
    ENV_IDS = ()
