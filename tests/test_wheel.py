"""A wheel built from the repo, installed in a fresh venv outside the repo, makes every env with every
domain and asset source: static assets and textures ship inside the wheel."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

CHECK = textwrap.dedent(
    """
    import gymnasium as gym, mani_skill_space
    from pathlib import Path
    from mani_skill_space.envs import task_class
    assert not Path(mani_skill_space.__file__).resolve().is_relative_to(Path(REPO)), mani_skill_space.__file__
    made = 0
    for env_id in mani_skill_space.ENV_IDS:
        cls = task_class(env_id)
        for domain in cls.SUPPORTED_DOMAINS:
            for source in cls.SUPPORTED_ASSET_SOURCES:
                env = gym.make(env_id, domain=domain, asset_source=source, obs_mode="rgbd", render_backend="cpu")
                env.reset(seed=0)
                env.step(env.action_space.sample())
                env.close()
                made += 1
    print("made", made)
    """
)


@pytest.mark.slow
def test_wheel_installed_outside_the_repo_makes_every_env(tmp_path):
    subprocess.run([sys.executable, "-m", "build", "--wheel", "--outdir", str(tmp_path / "dist"), str(REPO)], check=True, capture_output=True)
    (wheel,) = (tmp_path / "dist").glob("mani_skill_space-*.whl")
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    pip = [str(venv / "bin" / "python"), "-m", "pip", "install", "-q", "-c", str(REPO / "constraints.txt")]
    subprocess.run(pip + ["torch==2.13.0"], check=True, capture_output=True)
    subprocess.run(pip + [str(wheel)], check=True, capture_output=True)
    result = subprocess.run(
        [str(venv / "bin" / "python"), "-c", CHECK.replace("REPO", repr(str(REPO)))], cwd=tmp_path, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr[-3000:]
    import mani_skill_space
    from mani_skill_space.envs import task_class

    expected = sum(len(task_class(i).SUPPORTED_DOMAINS) * len(task_class(i).SUPPORTED_ASSET_SOURCES) for i in mani_skill_space.ENV_IDS)
    assert result.stdout.split()[-1] == str(expected)
