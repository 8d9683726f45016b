from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch

from mani_skill_space.envs import SolarPanelAssemblyEnv
from mani_skill_space.envs.solar_panel_assembly import FILL_ORDER, PANEL_START_XY, PEG_REST_XY, REWARD_TABLE
from mani_skill_space.geometry import rotation_6d

ENV_ID = "SolarPanelAssembly-v1"
DOMAINS = SolarPanelAssemblyEnv.SUPPORTED_DOMAINS
SOURCES = SolarPanelAssemblyEnv.SUPPORTED_ASSET_SOURCES


def make(**kwargs):
    kwargs.setdefault("render_backend", "none")
    kwargs.setdefault("obs_mode", "state")
    return gym.make(ENV_ID, **kwargs)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(asset_source="dataset", clearance=0.002), "clearance applies to procedural assets only"),
        (dict(clearance=0.0), "clearance must be positive"),
    ],
)
def test_bad_kwargs(kwargs, message):
    with pytest.raises(ValueError, match=message):
        make(**kwargs)


@pytest.mark.parametrize("domain", ["moon", "orbit"])
def test_pegs_and_panel_start_at_rest_where_they_belong(domain):
    env = make(domain=domain)
    for seed in range(2):
        env.reset(seed=seed)
        u = env.unwrapped
        start = [p.pose.raw_pose.clone() for p in u.pegs] + [u.panel.pose.raw_pose.clone()]
        for _ in range(20):
            env.step(torch.zeros(1, 7))
        now = [p.pose.raw_pose for p in u.pegs] + [u.panel.pose.raw_pose]
        # a squashed many-sided peg may roll onto a steadier side: it settles, it does not wander off
        for before, after in zip(start, now):
            assert torch.linalg.norm(after[:, :3] - before[:, :3]).item() < 0.01, (domain, seed)
        assert torch.linalg.norm(u.panel.pose.p - start[-1][:, :3]).item() < 0.005
        for peg, rest in zip(u.pegs, PEG_REST_XY):
            assert torch.linalg.norm(peg.pose.p[0, :2] - torch.tensor(rest)).item() < 0.02
        assert torch.linalg.norm(u.panel_seat()[0, :2, 3] - torch.tensor(PANEL_START_XY)).item() < 0.03
        assert u.evaluate()["stage"].item() == 0
    env.close()


def _insert(env, socket: int, peg: int = None, lift: float = 0.0):
    u = env.unwrapped
    peg = socket if peg is None else peg
    goal = u.insertion.hole_bottom[0, socket].numpy().astype(np.float64).copy()
    goal[2, 3] += 1e-4 + lift
    u.pegs[peg].set_pose(sapien.Pose(goal @ np.linalg.inv(u.insertion.peg_ends[0, peg, 0].numpy().astype(np.float64))))


def _place_panel(env, offset=(0.0, 0.0, 0.0), yaw: float = 0.0):
    u = env.unwrapped
    goal = u.panel_target[0].numpy().astype(np.float64).copy()
    c, s = np.cos(yaw), np.sin(yaw)
    goal[:3, :3] = goal[:3, :3] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    goal[:3, 3] += np.array(offset) + [0.0, 0.0, 1e-4]
    u.panel.set_pose(sapien.Pose(goal @ np.linalg.inv(u._seat_in_panel[0].numpy().astype(np.float64))))


def _raise_panel(env, height: float):
    u = env.unwrapped
    pose = u.panel.pose.sp
    u.panel.set_pose(sapien.Pose(pose.p + np.array([0.0, 0.0, height]), pose.q))


@pytest.mark.parametrize("asset_source", SOURCES)
def test_success_needs_four_pegs_in_and_the_panel_seated(asset_source):
    env = make(asset_source=asset_source)
    env.reset(seed=2)
    u = env.unwrapped
    for socket in range(4):
        _insert(env, socket)
    _place_panel(env)
    assert u.evaluate()["success"].item()
    _place_panel(env, yaw=np.pi)  # the panel looks the same turned half round
    assert u.evaluate()["success"].item()
    _place_panel(env, offset=(0.015, 0.0, 0.0))
    assert not u.evaluate()["success"].item()
    _place_panel(env, yaw=np.radians(8))
    assert not u.evaluate()["success"].item()
    _place_panel(env)
    _insert(env, 1, lift=0.5 * u.insertion.hole_depth[0, 0].item())  # half way out
    info = u.evaluate()
    assert not info["success"].item() and info["socket_filled"][0].tolist() == [True, False, True, True]
    # pegs of one length may swap sockets; a short peg in a long peg's socket does not count
    _insert(env, 1, peg=0)
    _insert(env, 0, peg=1)
    assert u.evaluate()["socket_filled"][0].tolist() == [True, True, True, True]
    _insert(env, 2, peg=1, lift=0.3)  # peg 1 out of the way, high above
    _insert(env, 0, peg=2)
    assert not u.evaluate()["socket_filled"][0, 0].item()
    env.close()


def _normalized(env, panel_grasped: bool = False) -> float:
    u = env.unwrapped
    info = u.evaluate()
    if panel_grasped:
        info["panel_grasped"] = torch.ones_like(info["panel_grasped"])
        info["success"] = torch.zeros_like(info["success"])
    terms = REWARD_TABLE.weighted({**u._reward_inputs(info), **u._penalty_inputs()})
    return REWARD_TABLE.normalize(REWARD_TABLE.dense(terms, info["success"])).item()


@pytest.mark.parametrize("asset_source", SOURCES)
def test_reward_rises_strictly_through_the_stages(asset_source):
    env = make(asset_source=asset_source, reward_mode="normalized_dense")
    env.reset(seed=4)
    u = env.unwrapped
    rewards, stages = [_normalized(env)], [u.evaluate()["stage"].item()]
    for socket in (2, 3, 0, 1):
        _insert(env, socket)
        rewards.append(_normalized(env))
        stages.append(u.evaluate()["stage"].item())
    rewards.append(_normalized(env, panel_grasped=True))  # panel grasped on the deck
    _raise_panel(env, 0.1)
    rewards.append(_normalized(env, panel_grasped=True))  # lifted
    _place_panel(env, offset=(0.0, 0.0, 0.03))
    rewards.append(_normalized(env, panel_grasped=True))  # over its target
    _place_panel(env)
    rewards.append(_normalized(env, panel_grasped=True))  # seated, still held
    rewards.append(_normalized(env))  # released: success
    assert stages == [0, 1, 2, 3, 4]
    assert all(b > a for a, b in zip(rewards, rewards[1:])), rewards
    assert rewards[-1] == pytest.approx(1.0)
    assert u.evaluate()["stage"].item() == 8
    env.close()


def test_success_gives_the_maximum_reward():
    env = make(reward_mode="dense")
    env.reset(seed=0)
    for socket in range(4):
        _insert(env, socket)
    _place_panel(env)
    info = env.unwrapped.get_info()
    assert info["success"].item()
    assert env.unwrapped.get_reward(obs=None, action=torch.zeros(1, 7), info=info).item() == REWARD_TABLE.max_reward
    env.close()


def test_seated_panel_stays_on_the_pegs():
    for domain in ("moon", "earth"):
        env = make(domain=domain, control_mode="pd_joint_pos")
        env.reset(seed=1)
        for socket in range(4):
            _insert(env, socket)
        _place_panel(env)
        hold = env.unwrapped.agent.robot.get_qpos()[:, :8].clone()
        for _ in range(40):
            env.step(hold)
        assert env.unwrapped.evaluate()["success"].item(), domain
        env.close()


def test_state_observations():
    env = make(obs_mode="state_dict")
    obs, _ = env.reset(seed=0)
    extra = obs["extra"]
    for key, size in [
        ("pegs_pos_in_tcp", 12),
        ("pegs_rot6d_in_tcp", 24),
        ("sockets_pos_in_tcp", 12),
        ("target_entrances_in_peg_ends", 12),
        ("target_bottoms_in_peg_ends", 12),
        ("target_sockets_rot6d_in_peg_ends", 24),
        ("socket_filled", 4),
        ("peg_inserted", 4),
        ("handle_pos_in_tcp", 3),
        ("target_pos_in_seat", 3),
        ("target_rot6d_in_seat", 6),
        ("wrist_wrench", 6),
        ("next_peg", 4),
        ("next_peg_grasped", 1),
        ("next_peg_pos_in_tcp", 3),
        ("next_peg_rot6d_in_tcp", 6),
        ("next_entrance_in_peg_end", 3),
        ("next_bottom_in_peg_end", 3),
        ("next_socket_rot6d_in_peg_end", 6),
    ]:
        assert extra[key].shape == (1, size), key
    env.close()


def test_next_peg_is_the_held_one_else_the_first_waiting_in_fill_order():
    """Batched over 8 synthetic envs: a held peg is next whatever is inserted; else the first of FILL_ORDER (2, 3, 0,
    1) not yet inserted; once all are in, the last of the order."""
    grasped = torch.zeros(8, 4, dtype=torch.bool)
    inserted = torch.zeros(8, 4, dtype=torch.bool)
    inserted[1, 2] = True
    inserted[2, [2, 3]] = True
    inserted[3, [2, 3, 0]] = True
    inserted[4] = True
    grasped[5, 0] = True
    grasped[6, 3] = True
    inserted[6, 2] = True
    inserted[7, [3, 0]] = True  # 2 waits (a peg that came out): it is next again
    scene = SimpleNamespace(device=torch.device("cpu"))
    assert FILL_ORDER == (2, 3, 0, 1)
    assert SolarPanelAssemblyEnv._next_peg(scene, grasped, inserted).tolist() == [2, 3, 0, 1, 1, 0, 3, 2]


def test_next_peg_observation_repeats_that_pegs_own_slots():
    env = make(obs_mode="state_dict")
    env.reset(seed=0)
    _insert(env, 2)
    u = env.unwrapped
    extra = u.get_obs(u.get_info())["extra"]
    assert extra["next_peg"][0].tolist() == [0.0, 0.0, 0.0, 1.0]  # 2 is in: 3 is next
    assert extra["next_peg_grasped"].item() == 0.0
    assert torch.equal(extra["next_peg_pos_in_tcp"][0], extra["pegs_pos_in_tcp"].reshape(4, 3)[3])
    assert torch.equal(extra["next_peg_rot6d_in_tcp"][0], extra["pegs_rot6d_in_tcp"].reshape(4, 6)[3])
    assert torch.equal(extra["next_entrance_in_peg_end"][0], extra["target_entrances_in_peg_ends"].reshape(4, 3)[3])
    assert torch.equal(extra["next_bottom_in_peg_end"][0], extra["target_bottoms_in_peg_ends"].reshape(4, 3)[3])
    assert torch.equal(extra["next_socket_rot6d_in_peg_end"][0], extra["target_sockets_rot6d_in_peg_ends"].reshape(4, 6)[3])
    env.close()


def test_each_peg_observes_its_target_socket_from_its_end():
    env = make(obs_mode="state_dict")
    env.reset(seed=0)
    u = env.unwrapped
    _insert(env, 2, lift=0.05)  # peg 2 held on its socket's axis, its end 5 cm (and _insert's 0.1 mm) above the bottom
    _insert(env, 0, peg=1)  # peg 1 in peg 0's socket: peg 0 now targets the other long socket
    extra = u.get_obs(u.get_info())["extra"]
    bottoms = extra["target_bottoms_in_peg_ends"].reshape(4, 3)
    entrances = extra["target_entrances_in_peg_ends"].reshape(4, 3)
    rotations = extra["target_sockets_rot6d_in_peg_ends"].reshape(4, 6)
    depth = u.insertion.hole_depth[0, 2].item()
    assert torch.linalg.norm(bottoms[2]).item() == pytest.approx(0.0501, abs=1e-5)
    assert torch.linalg.norm(entrances[2]).item() == pytest.approx(0.0501 - depth, abs=1e-5)
    assert torch.allclose(rotations[2], rotation_6d(torch.eye(3)), atol=1e-4)
    other_long_socket = u.insertion.hole_bottom[0, 1, :3, 3]
    peg_0_ends = u.peg_end_frames()[0, 0, :, :3, 3]
    distances = torch.linalg.norm(peg_0_ends - other_long_socket, dim=-1)
    assert torch.linalg.norm(bottoms[0]).item() == pytest.approx(distances[u.get_info()["pair_peg_end"][0, 0, 1]].item(), abs=1e-4)
    assert torch.linalg.norm(bottoms[1]).item() == pytest.approx(1e-4, abs=1e-5)  # peg 1 keeps the socket it is in
    env.close()


def test_target_socket_is_the_one_a_peg_stands_in_else_its_own_unless_taken():
    """Batched over 8 synthetic envs, ``in_socket[env, peg, socket]``: a peg inserted anywhere targets that socket;
    one that is out targets its own socket unless another peg fills it, then the other of its length."""
    in_socket = torch.zeros(8, 4, 4, dtype=torch.bool)
    in_socket[1, 2, 2] = True  # 2 in its own socket: keeps it
    in_socket[2, 3, 2] = True  # 3 in 2's socket: 3 keeps it, 2 targets 3's
    in_socket[3, 0, 1] = True  # 0 in 1's socket: 0 keeps it, 1 targets 0's
    in_socket[4] = torch.eye(4, dtype=torch.bool)  # all home
    in_socket[5, 1, 0] = in_socket[5, 0, 1] = True  # swapped: each keeps the one it is in
    in_socket[6, 2, 2] = in_socket[6, 1, 1] = True
    in_socket[7, 3, 3] = in_socket[7, 1, 0] = True
    info = dict(peg_in_socket=in_socket, socket_filled=in_socket.any(dim=1))
    scene = SimpleNamespace(device=torch.device("cpu"))
    assert SolarPanelAssemblyEnv.target_sockets(scene, info).tolist() == [
        [0, 1, 2, 3],
        [0, 1, 2, 3],
        [0, 1, 3, 2],
        [1, 0, 2, 3],
        [0, 1, 2, 3],
        [1, 0, 2, 3],
        [0, 1, 2, 3],
        [1, 0, 2, 3],
    ]
