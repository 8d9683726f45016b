import os

import pytest


@pytest.fixture(autouse=True, scope="session")
def _isolated_cache(tmp_path_factory):
    """Keep the tests' CoACD/array cache out of the user's ~/.cache."""
    os.environ["MANI_SKILL_SPACE_CACHE"] = str(tmp_path_factory.mktemp("cache"))
    yield
