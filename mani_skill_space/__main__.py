"""``python -m mani_skill_space COMMAND ARGS``: the ``mani-skill-space`` command (see ``mani_skill_space.cli``)."""

from mani_skill_space.cli import main

if __name__ == "__main__":
    main()
