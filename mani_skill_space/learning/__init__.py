"""What the learning baselines (``baselines/``) share with the evaluation CLI.

- ``observations``: observation encoding for the networks (state, or state plus RGB-D) and the state vector's
  layout (which columns each entry fills);
- ``networks``: PPO's actor-critic, SAC's actor, the BC MLP and the diffusion policy's denoiser;
- ``checkpoints``: saving, safe loading (tensors and plain data only) and ``CheckpointPolicy``, which the
  evaluation CLI runs for ``--policy checkpoint:PATH``; ``BestCheckpoint`` keeps the best one seen in training;
- ``vector_env``: vectorised training envs (GPU-batched, or CPU worker processes);
- ``curves``: learning curves (CSV and PNG);
- ``demonstrations``: ManiSkill trajectory files as the imitation learners read them (and DAgger's labelled states);
- ``schedules``: the imitation learners' learning-rate schedules.

Baselines evaluate during training with ``mani_skill_space.rollout.evaluate_policy``: the evaluation CLI's
protocol and code.
"""

from mani_skill_space.learning.checkpoints import BestCheckpoint, CheckpointError, CheckpointPolicy, load_checkpoint, load_model, save_checkpoint
from mani_skill_space.learning.curves import LearningCurve
from mani_skill_space.learning.demonstrations import RECORDING_KWARGS, load_demonstrations, load_labelled_states, task_of_demonstrations
from mani_skill_space.learning.networks import (
    MODELS,
    OBS_CLIP,
    BehaviourCloningPolicy,
    DiffusionNoisePredictor,
    DiffusionUnetNoisePredictor,
    GaussianActorCritic,
    ObservationEncoder,
    SquashedGaussianActor,
    denoise,
    mlp,
)
from mani_skill_space.learning.observations import IMAGE_OBS_MODES, STATE_OBS_MODES, encode_observation, observed_dims, state_layout
from mani_skill_space.learning.schedules import LR_SCHEDULES, LrSchedule, set_learning_rate
from mani_skill_space.learning.vector_env import VectorEnv

__all__ = [
    "BehaviourCloningPolicy",
    "BestCheckpoint",
    "CheckpointError",
    "CheckpointPolicy",
    "DiffusionNoisePredictor",
    "DiffusionUnetNoisePredictor",
    "GaussianActorCritic",
    "IMAGE_OBS_MODES",
    "LR_SCHEDULES",
    "LearningCurve",
    "LrSchedule",
    "MODELS",
    "OBS_CLIP",
    "ObservationEncoder",
    "RECORDING_KWARGS",
    "STATE_OBS_MODES",
    "SquashedGaussianActor",
    "VectorEnv",
    "denoise",
    "encode_observation",
    "load_checkpoint",
    "load_demonstrations",
    "load_labelled_states",
    "load_model",
    "mlp",
    "observed_dims",
    "save_checkpoint",
    "set_learning_rate",
    "state_layout",
    "task_of_demonstrations",
]
