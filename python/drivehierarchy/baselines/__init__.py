"""RL and imitation baselines for `DriveHierarchy-R4` (the `rl` extra): RL-ready wrappers
(`wrappers`), PPO/SAC training (`rl`), expert demonstrations, BC and DAgger (`imitation`), and the
`model.zip` format every trained policy is saved in (`model_io`); `drivehierarchy.agents.sb3`
drives a saved policy through the benchmark harness. See docs/baselines.md."""

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
    "SuiteEnv",
    "WrapperConfig",
    "make_env",
    "split_suite",
]
