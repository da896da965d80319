"""`DriveHierarchy-R4`: the closed-loop rank as a Gymnasium environment over the Rust world.

One `step()` is one policy decision: the action is held for `decision_interval_ticks` ticks of
0.05 s (5 → the protocol's 4 Hz). As in the original runner, `reset()` plays ticks 1–4 with zero
control and returns the state after tick 4 (`info["tick"] == 4`), where the policy is first asked
(`warmup_ticks=0` asks at t = 0 instead).

In decision mode an action is `[steer, target_speed_mps]`, or a raw VLM reply (`str`, parsed in
Rust by the protocol's parser), or `None` for "no decision" (a transport error): a reply without
a usable decision holds the previous control verbatim and counts in `parse_failures`. Each step's
`info["reply"]` says what was received, parsed and applied; `sim.decision_log()` has them all.

Rewards sum to the episode's S_R4 / 100: each step pays the gain in route score, and the last
step adds the difference between the final composed score and the route score.
"""

from __future__ import annotations

import string
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from drivehierarchy import _core
from drivehierarchy._core import ConfigError, SimulationError
from drivehierarchy._heap import release_free_heap
from drivehierarchy.envs.config import R4Config
from drivehierarchy.envs.traffic.modes import resolve_traffic_mode, warn_deprecated_scenario_mode
from drivehierarchy.envs.traffic.transport import make_sumo_traffic, needs_new_session
from drivehierarchy.scenarios import resolve_scenario, sumo_home

STATE_FIELDS: tuple[str, ...] = tuple(_core.STATE_FIELDS)
PROMPT_MAX_CHARS = 8192
# Finite bounds for the state vector (metres, m/s, radians all stay far below this).
STATE_BOUND = 1.0e6
# Every character the prompt can contain (digits, letters, punctuation, space, newline).
PROMPT_CHARSET = frozenset(string.printable)


class EpisodeNotStarted(SimulationError, gym.error.ResetNeeded):
    """A step or render on an env with no running episode: Gymnasium's `ResetNeeded`, and a
    `SimulationError` like every other failure of the world."""


# Waypoint actions live in this box (metres, ego frame): 30 m/s over a 64-point plan of 10 s steps
# is far inside it; the tracker clips anything beyond ±200 m.
WAYPOINT_BOUND_M = 200.0
# Meta actions: `MultiDiscrete([len(PATH_ACTIONS), len(SPEED_ACTIONS)])`.
PATH_ACTIONS: tuple[str, ...] = (
    "FOLLOW_LANE",
    "CHANGE_LANE_LEFT",
    "CHANGE_LANE_RIGHT",
    "GO_STRAIGHT",
    "TURN_LEFT",
    "TURN_RIGHT",
)
SPEED_ACTIONS: tuple[str, ...] = ("KEEP", "ACCELERATE", "DECELERATE", "STOP")


def action_space(config: R4Config) -> spaces.Space[Any]:
    """The action space of one env with `config`'s action mode."""
    if config.action_mode == "decision":
        return spaces.Box(
            np.array([-1.0, 0.0], np.float32), np.array([1.0, 30.0], np.float32), dtype=np.float32
        )
    if config.action_mode == "waypoints":
        b = WAYPOINT_BOUND_M
        return spaces.Box(-b, b, (config.waypoints, 2), np.float32)
    if config.action_mode == "meta":
        return spaces.MultiDiscrete([len(PATH_ACTIONS), len(SPEED_ACTIONS)])
    return spaces.Box(
        np.array([0.0, 0.0, -1.0], np.float32), np.array([1.0, 1.0, 1.0], np.float32), dtype=np.float32
    )


def single_spaces(config: R4Config) -> tuple[spaces.Dict, spaces.Space[Any]]:
    """The observation and action spaces of one env with `config` (the single env's, and the
    native vector env's per-env spaces)."""
    obs: dict[str, spaces.Space[Any]] = {}
    if config.front is not None:
        obs["front"] = spaces.Box(0, 255, (config.front.height, config.front.width, 3), np.uint8)
    if config.bev is not None:
        obs["bev"] = spaces.Box(0, 255, (config.bev.size_px, config.bev.size_px, 3), np.uint8)
    if config.prompt:
        obs["prompt"] = spaces.Text(max_length=PROMPT_MAX_CHARS, min_length=0, charset=PROMPT_CHARSET)
    obs["state"] = spaces.Box(-STATE_BOUND, STATE_BOUND, (len(STATE_FIELDS),), np.float32)
    return spaces.Dict(obs), action_space(config)


class DriveHierarchyR4Env(gym.Env[dict[str, Any], np.ndarray]):
    """The DriveHierarchy R4 closed-loop rank: one scenario of the suite (or any scenario file).

    **Observation** (`spaces.Dict`; keys present as configured):

    - `front`: `Box(0, 255, (H, W, 3), uint8)`, the protocol's front camera (default 450×800);
      `front=None` drops it.
    - `bev`: `Box(0, 255, (S, S, 3), uint8)`, bird's-eye view with the local route (default
      800×800); `bev=None` drops it.
    - `prompt`: `Text`, the exact route prompt the protocol sends a VLM at each decision.
    - `state`: `Box(float32)`, privileged ego/route scalars named by `STATE_FIELDS`.

    **Action** (`action_mode`): `"decision"` (default) takes `[steer, target_speed_mps]` in
    `[-1, 1] × [0, 30]` (steer < 0 turns left), a raw VLM reply `str` (parsed in Rust by the
    protocol's parser) or `None` (no reply; the previous control is held and counted);
    `"raw"` takes `[throttle, brake, steer]` in `[0, 1] × [0, 1] × [-1, 1]`. `"waypoints"` takes
    `(K, 2)` ego-frame points (x forward, y left, metres; `Box`), `"meta"` `[path, speed]`
    indices into `PATH_ACTIONS` × `SPEED_ACTIONS` (`MultiDiscrete([6, 4])`); both run through the
    waypoint tracker and also take a raw reply `str` of their level (docs/r4.md#action-levels).

    **Arguments**: `scenario` (a suite id such as `"07_sudden_brake/town01_07_lead_brakes"`,
    or a path to a scenario file), `config` (an `R4Config` or a dict of its fields),
    `render_mode="rgb_array"` (`render()` returns the front camera, read-only), and any
    `R4Config` field as a keyword (`front=None`, `traffic="idm"`, `action_mode="raw"`, …).
    `reset(options={"scenario": ...})` switches the scenario.

    **Episode end**: `terminated` is True on any of the protocol's terminations — destination
    reached, collision, off-road timeout (31st consecutive off-road tick), route deviation,
    blocked, or the scenario timeout at 2 × the scenario duration (`info["time_limit_s"]`,
    `info["time_left_s"]`). `truncated` is always False: the protocol's own timeout ends every
    episode, so no external time limit is needed. Rewards sum to S_R4 / 100.

    Copies (`copy.deepcopy`, pickle) keep the scenario and config but no episode: call `reset()`
    before stepping them (stepping raises `gymnasium.error.ResetNeeded`). After `close()` every
    call raises `gymnasium.error.ClosedEnvironmentError`.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 4}  # type: ignore[misc]

    def __init__(
        self,
        scenario: str | Path | None = None,
        config: R4Config | dict[str, Any] | None = None,
        render_mode: str | None = None,
        *,
        scenario_text: str | None = None,
        **overrides: Any,
    ) -> None:
        if isinstance(config, dict):
            config = R4Config.from_dict(config)
        config = config or R4Config()
        if overrides:
            config = R4Config.from_dict({**_shallow(config), **overrides})
        if scenario is not None:
            config = config.replace(scenario=str(scenario))
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(f"config `render_mode` = {render_mode!r}: expected one of ['rgb_array']")
        self.config = config
        self.render_mode = render_mode
        self._sim: _core.Sim | None = None
        self._scenario_path: str | None = None
        self._sumo: _core.SumoSession | None = None
        self._closed = False
        self._live = False  # an episode is running (reset since the last load/copy)
        # The scenario's TOML standing for the file (the editor's unsaved buffer), or None.
        self._scenario_text = scenario_text
        self._load(config.scenario)

        self.observation_space, self.action_space = single_spaces(config)
        self._last_frame: np.ndarray | None = None

    # -- loading -------------------------------------------------------------------------
    def _load(self, scenario: str | None) -> None:
        # A buffer stands for its file, which need not exist yet.
        path = str(scenario) if self._scenario_text is not None else resolve_scenario(scenario)
        if self._sim is not None and path == self._scenario_path:
            return
        self._live = False
        text, self._scenario_text = self._scenario_text, None  # only for the first scenario
        self._sim = _core.Sim(path, self.config.to_core(), sumo_home(), text)
        warn_deprecated_scenario_mode(path, text)
        self._scenario_path = path
        self._configure_traffic()

    @property
    def scenario_path(self) -> str:
        assert self._scenario_path is not None
        return self._scenario_path

    @property
    def sim(self) -> _core.Sim:
        """The Rust episode (privileged access for experts, runners and tests)."""
        if self._sim is None:
            raise gym.error.ClosedEnvironmentError(
                "sim of a closed DriveHierarchy-R4 env: make a new env (gym.make) instead"
            )
        return self._sim

    # -- Gymnasium API ---------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        self._check_open("reset")
        super().reset(seed=seed)
        options = dict(options or {})
        scenario = options.pop("scenario", None)
        if options:
            key = sorted(options)[0]
            raise ConfigError(
                f"config `options.{key}` = {options[key]!r}: unknown reset option (known: scenario)"
            )
        if scenario is not None:
            self._load(str(scenario))
        # The world seed comes from the env's np_random so seeding follows Gymnasium semantics.
        world_seed = int(self.np_random.integers(0, 2**63 - 1))
        if self.traffic_mode == "sumo" and needs_new_session(self._sumo, self.config.sumo_backend):
            # First SUMO env of the process on libsumo, the others ("auto") on TraCI.
            self._close_traffic()
            self._configure_traffic()
        # The scenario's variation follows the given seed itself: seed 0 plays the scenario as
        # written, other seeds jitter it within its `[variation]` bounds; unseeded resets vary.
        variation = int(seed) if seed is not None else world_seed
        obs, info = self.sim.reset(world_seed, variation)
        self._last_frame = None
        self._live = True
        return self._shape_obs(obs), info

    def step(self, action: Any) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        if action is None or isinstance(action, str):
            return self.step_reply(action)
        self._check_live("step")
        arr = np.asarray(action, dtype=np.float64)
        expected = self.action_space.shape
        if arr.shape != expected:
            raise ConfigError(f"config `action` = {action!r}: expected shape {expected}, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ConfigError(f"config `action` = {action!r}: contains NaN or infinity")
        obs, reward, terminated, truncated, info = self.sim.step(arr.reshape(-1))
        self._last_frame = None
        return self._shape_obs(obs), float(reward), bool(terminated), bool(truncated), info

    def step_reply(self, reply: str | None) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        """One decision from a raw VLM reply (`None`: no reply at all, e.g. a transport error).

        The reply is parsed in Rust by the protocol's parser (docs/protocol.md#r4-actuation); when
        it yields no decision the previous control is held verbatim (the steer rate-limit state
        untouched) and the failure is counted in the score record's `parse_failures` and logged in
        `info["reply"]`.
        """
        if self.config.action_mode == "raw":
            raise ConfigError(
                f"config `action` = {reply!r}: raw replies need action_mode 'decision', 'waypoints' "
                f"or 'meta' (this env is {self.config.action_mode!r})"
            )
        if reply is not None and not isinstance(reply, str):
            raise ConfigError(f"config `action` = {reply!r}: a reply must be a str or None")
        self._check_live("step_reply")
        if reply is not None and not reply.isascii():
            # A lone surrogate (what a JSON "\ud800" escape decodes to) is no Unicode text and
            # cannot cross into Rust: it becomes U+FFFD, like any undecodable byte of a reply.
            reply = reply.encode("utf-16", "surrogatepass").decode("utf-16", "replace")
        obs, reward, terminated, truncated, info = self.sim.step_reply(reply)
        self._last_frame = None
        return self._shape_obs(obs), float(reward), bool(terminated), bool(truncated), info

    def decision_log(self) -> list[dict[str, Any]]:
        """Every decision of the episode: decision, tick, raw reply, parsed action, failure, control."""
        self._check_open("decision_log")
        return self.sim.decision_log()

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        self._check_live("render")
        if self._last_frame is None:
            frame = self.sim.render("front")
            # Read-only: the frame is cached until the next step, so a caller's in-place edit
            # would otherwise corrupt what the next render() call returns.
            frame.setflags(write=False)
            self._last_frame = frame
        return self._last_frame

    def close(self) -> None:
        had_world = self._sim is not None
        self._close_traffic()
        self._sim = None
        self._closed = True
        self._live = False
        if had_world:
            release_free_heap()  # the world's pages, back to the OS (drivehierarchy._heap)

    def _check_open(self, what: str) -> None:
        if self._closed:
            raise gym.error.ClosedEnvironmentError(
                f"{what}() on a closed DriveHierarchy-R4 env: make a new env (gym.make) instead"
            )

    def _check_live(self, what: str) -> None:
        self._check_open(what)
        if not self._live:
            raise EpisodeNotStarted(
                f"{what}() before reset(): this env has no running episode (a new, copied or "
                "unpickled env starts without one; call reset() first)"
            )

    # -- helpers ---------------------------------------------------------------------------
    def _shape_obs(self, raw: dict[str, Any]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        assert isinstance(self.observation_space, gym.spaces.Dict)
        for key in self.observation_space.spaces:
            out[key] = raw[key]
        return out

    def expert_action(self) -> np.ndarray:
        """The privileged autopilot's action for the current state, in this env's action mode
        (at the waypoint and meta levels its plan: the level's oracle)."""
        self._check_open("expert_action")
        raw = self.sim.expert_action()
        if self.config.action_mode == "meta":
            return np.asarray(raw, dtype=np.int64)
        if self.config.action_mode == "waypoints":
            return np.asarray(raw, dtype=np.float32).reshape(self.config.waypoints, 2)
        return np.asarray(raw, dtype=np.float32)

    def score(self) -> dict[str, Any]:
        """The scene score record so far (final once the episode has terminated)."""
        self._check_open("score")
        return self.sim.score()

    # -- background traffic (envs/traffic) -----------------------------------------------------
    @property
    def traffic_mode(self) -> str:
        """The background-traffic mode in effect: "sumo", "idm" or "none"."""
        return resolve_traffic_mode(self.config.traffic, self.sim.scenario_traffic_mode)

    def _configure_traffic(self) -> None:
        mode = self.traffic_mode
        if mode == "sumo":
            if self._sumo is None:
                self._sumo = make_sumo_traffic(self.config.sumo_backend)
            self.sim.set_traffic("sumo", self._sumo)
        else:
            self._close_traffic()
            self.sim.set_traffic(mode)

    def release_traffic(self) -> None:
        """Stops this env's SUMO simulation, if it runs one (the next `reset` starts a fresh one).

        libsumo holds one simulation per process: an env that stays idle while another env of the
        same process needs SUMO (a scenario sampler switching scenarios, an evaluation loop) must
        release it first. The running episode cannot be stepped afterwards.
        """
        if self._sumo is not None:
            self._sumo.close()

    def _close_traffic(self) -> None:
        if self._sumo is not None:
            self._sumo.close()
            self._sumo = None

    def __getstate__(self) -> dict[str, Any]:
        # Pickled by config and the loaded scenario (+ seed on the next reset); the Rust world is
        # rebuilt on load, without an episode (Gymnasium's ResetNeeded until reset()).
        if self._closed:
            raise gym.error.ClosedEnvironmentError("cannot copy or pickle a closed DriveHierarchy-R4 env")
        return {"config": self.config, "render_mode": self.render_mode, "scenario": self._scenario_path}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(  # type: ignore[misc]
            scenario=state.get("scenario"), config=state["config"], render_mode=state["render_mode"]
        )


def _shallow(config: R4Config) -> dict[str, Any]:
    import dataclasses

    out: dict[str, Any] = {}
    for f in dataclasses.fields(config):
        v = getattr(config, f.name)
        out[f.name] = dataclasses.asdict(v) if dataclasses.is_dataclass(v) and not isinstance(v, type) else v
    return out
