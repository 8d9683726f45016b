"""Communication delay: the ring buffers (synthetic batched tensors) and the env's delayed actions and observations."""

import gymnasium as gym
import numpy as np
import pytest
import torch

import mani_skill_space  # noqa: F401
from mani_skill_space.delay import DelayLine, DelayRange, check_delay_kwargs, drift_moves, with_missing_replaced
from mani_skill_space.envs import task_class
from mani_skill_space.kwarg_checks import KwargError

N = 8


def _line(low, high, delays=None):
    line = DelayLine(N, DelayRange(low, high), "cpu")
    line.reset(torch.arange(N), torch.as_tensor(delays if delays is not None else [high] * N))
    return line


def test_the_largest_delay_reads_the_value_sent_that_many_steps_ago_not_the_newest():
    line = _line(0, 3)
    for step in range(1, 8):
        line.push(torch.full((N, 2), float(step)))
        value, missing = line.read()
        if step <= 3:
            assert missing.all()
        else:
            assert not missing.any() and (value == step - 3).all()


def test_each_env_reads_with_its_own_delay():
    delays = torch.arange(N) % 4
    line = _line(0, 3, delays)
    for step in range(1, 6):
        line.push(torch.arange(N, dtype=torch.float32)[:, None] * 100 + step)
    value, missing = line.read()
    assert not missing.any()
    assert value[:, 0].tolist() == [i * 100 + 5 - int(d) for i, d in enumerate(delays)]


def test_a_partial_reset_clears_only_the_reset_envs_and_stores_their_first_value():
    line = _line(2, 2)
    for step in range(1, 5):
        line.push({"x": torch.full((N, 1), float(step))})
    reset = torch.tensor([1, 5])
    line.reset(reset, torch.tensor([2, 2]), first={"x": torch.full((N, 1), -1.0)})
    line.push({"x": torch.full((N, 1), 5.0)})
    value, missing = line.read()
    assert missing.tolist() == [False] * N  # the reset envs read their stored first value
    kept = [i for i in range(N) if i not in (1, 5)]
    assert (value["x"][kept] == 3.0).all() and (value["x"][reset] == -1.0).all()


def test_missing_rows_are_replaced_and_drift_stays_in_range():
    value = torch.ones(N, 3)
    missing = torch.arange(N) < 3
    replaced = with_missing_replaced(value, missing, torch.zeros(N, 3))
    assert replaced[:3].sum() == 0 and (replaced[3:] == 1).all()
    moves = drift_moves(torch.tensor([0.01, 0.04, 0.06, 0.5] * 2), 0.1)
    assert moves.tolist() == [-1, -1, 1, 0] * 2
    line = _line(1, 3, [1, 3, 2, 2, 1, 3, 2, 2])
    line.drift(torch.tensor([-1, 1, 1, -1, 1, -1, 0, 0]))
    assert line.delay.tolist() == [1, 3, 3, 1, 2, 2, 2, 2]


def _run(actions, **kwargs):
    """Observations and TCP positions after the reset and after every step."""
    env = gym.make("SampleCollection-v1", obs_mode="state", render_backend="none", **kwargs)
    obs, _ = env.reset(seed=4)
    observations, positions = [obs.clone()], [env.unwrapped.agent.tcp.pose.p[0].clone()]
    for action in actions:
        obs, *_ = env.step(action)
        observations.append(obs.clone())
        positions.append(env.unwrapped.agent.tcp.pose.p[0].clone())
    env.close()
    return observations, torch.stack(positions)


def _actions(steps, gripper=1.0):
    actions = np.zeros((steps, 7), dtype=np.float32)
    actions[:, -1] = gripper
    actions[0, 0] = 1.0  # one push along x, then hold
    return actions


def test_an_action_delayed_three_steps_moves_the_hand_at_step_four_by_the_same_amount():
    _, plain = _run(_actions(7))
    _, delayed = _run(_actions(7), action_delay=3)
    torch.testing.assert_close(delayed[:4], delayed[:1].expand(4, 3), atol=1e-4, rtol=0)  # still until step 4
    assert delayed[4, 0] - delayed[0, 0] > 0.03
    torch.testing.assert_close(delayed[4:] - delayed[0], plain[1:5] - plain[0], atol=1e-3, rtol=0)


def test_an_observation_delayed_two_steps_is_the_undelayed_one_of_two_steps_before():
    actions = np.tile(np.array([0.3, -0.2, 0.1, 0.0, 0.0, 0.2, -1.0], dtype=np.float32), (6, 1))
    plain, _ = _run(actions)
    delayed, _ = _run(actions, observation_delay=2)
    for t in range(1, 7):
        torch.testing.assert_close(delayed[t], plain[max(t - 2, 0)])


def test_a_delay_range_is_drawn_per_episode_from_the_seed():
    env = gym.make("SampleCollection-v1", obs_mode="state", render_backend="none", action_delay=(0, 10))
    draws = []
    for seed in (1, 2, 3, 1):
        env.reset(seed=seed)
        draws.append(int(env.unwrapped._action_line.delay[0]))
    env.close()
    assert draws[0] == draws[3] and len(set(draws)) > 1


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(action_delay=-1), r"action_delay must be an int in \[0, 100\]"),
        (dict(observation_delay=(5, 2)), "min <= max"),
        (dict(observation_delay=2.5), "observation_delay must be an int"),
        (dict(action_delay=(1, 2, 3)), "a \\(min, max\\) pair"),
        (dict(delay_drift=1.5), "delay_drift must be a finite number >= 0 and <= 1"),
        (dict(action_delay=2, control_mode="pd_ee_pose"), "a delta mode or pd_joint_pos, not 'pd_ee_pose'"),
    ],
)
def test_bad_delay_kwargs_name_the_valid_range(kwargs, message):
    with pytest.raises(KwargError, match=message):
        task_class("SampleCollection-v1").check_task_kwargs(**kwargs)
    assert check_delay_kwargs({})["action_delay"] == DelayRange(0, 0)


@pytest.mark.parametrize("control_mode", ["pd_ee_delta_pose", "pd_joint_pos"])
def test_before_the_first_delayed_action_the_arm_and_gripper_hold_still(control_mode):
    env = gym.make("SampleCollection-v1", obs_mode="state", render_backend="none", control_mode=control_mode, action_delay=3)
    env.reset(seed=2)
    start = env.unwrapped.agent.robot.get_qpos().clone()
    for _ in range(3):
        env.step(env.action_space.sample() * 0 - 1.0)  # a far-off command (gripper closing), not applied yet
    moved = (env.unwrapped.agent.robot.get_qpos() - start).abs().max().item()
    env.close()
    assert moved < 2e-3
