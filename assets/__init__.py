"""Static data shipped with mani-skill-space: sky and ground textures and dataset objects.

Installed as the ``mani_skill_space.assets`` package; ``make_assets.py`` regenerates every file here.
"""
