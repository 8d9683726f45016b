"""The CPU shortcut of ``is_grasping`` (no contact query for an object out of the fingers' reach) gives ManiSkill's
answer at every step of an episode that grasps, carries and releases the object."""

import gymnasium as gym
import torch

from mani_skill_space.envs.base import FINGER_REACH, GRASP_MIN_FORCE
from mani_skill_space.oracles import oracle_for


def test_grasp_check_matches_maniskill_along_an_oracle_episode():
    env = gym.make("SampleCollection-v1", control_mode="pd_joint_pos", render_backend="none")
    u = env.unwrapped
    oracle = oracle_for("SampleCollection-v1")
    obs, _ = env.reset(seed=11)
    oracle.reset(env, 11)
    answers, skipped = [], 0
    for _ in range(150):
        obs, *_ = env.step(oracle.act(obs))
        ours = u.is_grasping(u.sample)
        answers.append(bool(ours[0]))
        assert torch.equal(ours, u.agent.is_grasping(u.sample, min_force=GRASP_MIN_FORCE))
        distance = torch.linalg.norm(u.sample.pose.p - u.agent.tcp.pose.p, dim=-1)
        skipped += bool((distance > u._graspable_radius["sample"] + FINGER_REACH).all())
    env.close()
    assert any(answers) and not all(answers)  # the episode both grasped the sample and did not
    assert skipped > 0  # and the shortcut was taken
