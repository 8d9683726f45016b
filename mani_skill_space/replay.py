"""ManiSkill's trajectory replay tool with mani-skill-space's envs registered.

    python -m mani_skill_space.replay --traj-path demos/SampleCollection-v1/motionplanning/<name>.h5 \\
        -c pd_ee_delta_pose -o state --save-traj

Same arguments as ``python -m mani_skill.trajectory.replay_trajectory`` (``--help`` lists them). That tool
calls ``gym.make`` on the recorded env id without importing third-party task packs; importing this module
first registers ours, here and in the tool's worker processes (which re-import this module).
"""

import multiprocessing as mp

from mani_skill.trajectory import replay_trajectory

import mani_skill_space  # noqa: F401  (registers the envs)

if __name__ == "__main__":
    mp.set_start_method("spawn")
    replay_trajectory.main(replay_trajectory.parse_args())
