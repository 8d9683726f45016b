"""Benchmark suites (TOML), shipped as ``mani_skill_space.tasks``: ``--suite smoke`` loads ``smoke.toml``.

See ``mani_skill_space.suites`` for the file format.
"""
