"""A user policy for the ``module:callable`` hook of the evaluation CLI (used by tests/test_eval.py)."""

import numpy as np


class OpenGripperPolicy:
    """Holds the arm still with the gripper open (pd_ee_delta_pose)."""

    def act(self, obs):
        return np.array([0, 0, 0, 0, 0, 0, 1.0], dtype=np.float32)


def make_policy():
    return OpenGripperPolicy()
