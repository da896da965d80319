"""RL and imitation baselines for `DriveHierarchy-R4` (the `rl` extra): RL-ready wrappers
(`wrappers`), the train/test splits (`splits`), PPO/SAC training (`rl`, on SB3 vec envs or the
native batch via `vec_sb3`), expert demonstrations, BC and DAgger (`imitation`), and the
`model.zip` format every trained policy is saved in (`model_io`); `drivehierarchy.agents.sb3`
drives a saved policy through the benchmark harness. See docs/baselines.md."""

from drivehierarchy.baselines.splits import Split, make_split, stratified_split
from drivehierarchy.baselines.wrappers import (
    ActionCodec,
    ObsCodec,
    RewardConfig,
    SuiteEnv,
    WrapperConfig,
    make_env,
    split_suite,
)

__all__ = [
    "ActionCodec",
    "ObsCodec",
    "RewardConfig",
    "Split",
    "SuiteEnv",
    "WrapperConfig",
    "make_env",
    "make_split",
    "split_suite",
    "stratified_split",
]
