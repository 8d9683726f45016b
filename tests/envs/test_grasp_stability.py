"""Grasped objects are solved with more PhysX position iterations than the rest of the scene
(``GRASPABLE_SOLVER_POSITION_ITERATIONS``), so that a light part held in the fingers stays there."""

import gymnasium as gym
import numpy as np
import pytest

from mani_skill_space.envs.base import GRASPABLE_SOLVER_POSITION_ITERATIONS
from mani_skill_space.oracles import oracle_for

GRASPABLES = {
    "SampleCollection-v1": lambda u: [u.sample],
    "PegInHoleAssembly-v1": lambda u: [u.peg],
    "DebrisCapture-v1": lambda u: [u.debris],
    "MultiPegInHoleAssembly-v1": lambda u: u.pegs,
    "MultiSampleCollection-v1": lambda u: u.samples,
    "SolarPanelAssembly-v1": lambda u: [*u.pegs, u.panel],
}


def _iterations(actors) -> set:
    return {body.solver_position_iterations for actor in actors for body in actor._bodies}


@pytest.mark.parametrize("env_id", sorted(GRASPABLES))
def test_grasped_objects_take_more_iterations_than_the_scene(env_id):
    env = gym.make(env_id, obs_mode="state", render_backend="none", asset_source="dataset")
    u = env.unwrapped
    assert _iterations(GRASPABLES[env_id](u)) == {GRASPABLE_SOLVER_POSITION_ITERATIONS}
    assert u.agent.robot._objs[0].solver_position_iterations == u.sim_config.scene_config.solver_position_iterations < GRASPABLE_SOLVER_POSITION_ITERATIONS
    env.close()


def test_a_scene_asking_for_more_iterations_gives_them_to_grasped_objects_too():
    more = GRASPABLE_SOLVER_POSITION_ITERATIONS + 10
    env = gym.make("PegInHoleAssembly-v1", obs_mode="state", render_backend="none", sim_config=dict(scene_config=dict(solver_position_iterations=more)))
    assert _iterations([env.unwrapped.peg]) == {more}
    env.close()


def test_a_light_peg_stays_in_the_fingers_while_the_wrist_turns_in_orbit():
    """Multi-Peg-in-Hole, orbit, seed 62016: the oracle lifts a 24 g procedural peg and swings it over its hole,
    turning the wrist. With the scene's 15 iterations the fingers sank 1.6 mm into it and it sprang out of them
    during the swing."""
    env = gym.make("MultiPegInHoleAssembly-v1", obs_mode="state", render_backend="none", control_mode="pd_joint_pos", domain="orbit", asset_source="procedural")
    u = env.unwrapped
    oracle = oracle_for("MultiPegInHoleAssembly-v1")
    obs, _ = env.reset(seed=62016)
    oracle.reset(env, 62016)
    peg_in_hand = lambda: np.linalg.inv(u.agent.tcp.pose.sp.to_transformation_matrix()) @ u.pegs[0].pose.sp.to_transformation_matrix()  # noqa: E731
    lifted = None
    while oracle.phase != "pre-insert":
        obs, *_ = env.step(oracle.act(obs))
        assert oracle.failure is None, oracle.failure
        if lifted is None and oracle.phase == "lift":
            lifted = peg_in_hand()
    assert lifted is not None
    np.testing.assert_allclose(peg_in_hand()[:3, 3], lifted[:3, 3], atol=0.002)
    env.close()
