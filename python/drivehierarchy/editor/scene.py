"""A scenario buffer played from reset by a reference driver: the scene at any time t.

Everything shown comes from the world (`_core.Sim` through the R4 env): actor poses, lights,
events, the score record and the frames. A player drives its world forward only, recording
every decision's state and what the renderers draw of it (`Sim.frame_snapshot`), so the scene
and the frames at any time already played are a lookup and a render, never a replay. A world
whose episode ended is closed at once; a player can also be asked to give its world up
(`release_world`: libsumo runs one SUMO per process, and the newest buffer should get it) and
replays from reset only if asked for a time beyond what it recorded (the drivers are
deterministic, so the replay is the same episode).
"""

from __future__ import annotations

import bisect
import functools
import io
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np

from drivehierarchy.envs.config import BevConfig, CameraConfig

# The views the editor and `scenario preview` render: the gallery's (front 2× supersampled).
FRONT = CameraConfig(supersample=2)
BEV = BevConfig()
# The editor's driver menu; any probe cell (`follower@6`, `constant@10`, ...) is accepted, by
# the same names as `scenario probe` and `r4 run --agent`.
DRIVERS = ("expert", "late_expert", "follower@8", "lights@8", "constant@8", "zero")
# The reference drivers of the editor's "Probe" (suite_probe cells): solvable (expert), graded
# (late expert), and not solvable blind (route follower, light-obeying follower).
PROBE_CELLS = ("expert", "late_expert", "follower@8", "lights@8")


def png_bytes(frame: np.ndarray) -> bytes:
    """A frame as PNG, as `scenario preview --time` writes it (zlib level 3: two thirds of the
    default level's time, for about a fifth more bytes; the preview is served on loopback)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(frame).save(buf, format="PNG", compress_level=3)
    return buf.getvalue()


def _locked(method: Callable[..., Any]) -> Callable[..., Any]:
    """Runs a player method under the player's lock (requests and the precompute thread share
    players; the world is stepped by one thread at a time)."""

    @functools.wraps(method)
    def wrapper(self: ScenePlayer, *args: Any, **kwargs: Any) -> Any:
        with self.lock:
            return method(self, *args, **kwargs)

    return wrapper


class ScenePlayer:
    """One buffer (`path` + `text`, or the file itself when `text` is None) driven by `driver`."""

    def __init__(self, path: str, text: str | None, *, seed: int = 0, driver: str = "expert") -> None:
        from drivehierarchy._core import ConfigError
        from drivehierarchy.suite_probe import _agent, parse_cell

        try:
            parse_cell(driver)
        except ConfigError as exc:
            raise ValueError(f"driver {driver!r}: {exc}") from None
        self.lock = threading.RLock()
        self.path = path
        self.text = text
        self.seed = seed
        self.driver = driver
        self._agent = _agent(driver)
        self.env: Any = None
        # Each decision's scene as the world's raw rows (made into the page's JSON when asked:
        # building dicts for every SUMO vehicle at every decision is a tenth of a replay's time).
        self._raw: list[tuple[Any, ...]] = []
        self.times: list[float] = []
        # What the renderers draw at each decision (`_core.Frame`), beside `states`.
        self.snapshots: list[Any] = []
        # PNGs by (decision index, view), rendered on request or ahead of it (`precompute_step`).
        self.frames: dict[tuple[int, str], bytes] = {}
        self.focus = 0  # the decision last asked for: precomputing starts there
        self.done = False
        self.score: dict[str, Any] | None = None
        self._open_world()

    @_locked
    def close(self) -> None:
        self.release_world()

    def release_world(self) -> None:
        """Closes the world (and its SUMO); what was recorded stays servable."""
        if self.env is not None:
            self.env.close()
            self.env = None

    def _open_world(self) -> None:
        """A world at the last recorded decision: reset, then the recorded decisions replayed."""
        from drivehierarchy.envs.r4 import DriveHierarchyR4Env

        # State only: frames are rendered on demand at the editor's (the gallery's) quality.
        self.env = DriveHierarchyR4Env(
            scenario=self.path, scenario_text=self.text, front=None, bev=None, prompt=False
        )
        self._obs, self._info = self.env.reset(seed=self.seed)
        self._agent.reset(self.env, self._info)
        self.live_index = 0
        if not self._raw:
            self._record()
        while self.live_index < len(self._raw) - 1:
            self._step()

    def _record(self) -> None:
        sim, info = self.env.sim, self._info
        self._raw.append(
            (
                sim.ego_array(),
                sim.actors_array(),
                sim.light_states(),
                [e.get("type") for e in info.get("events", [])],
                info.get("score_composed"),
                info.get("termination_reason"),
            )
        )
        self.times.append(float(info["time_s"]))
        self.snapshots.append(sim.frame_snapshot())

    @property
    def states(self) -> list[dict[str, Any]]:
        """Every recorded decision's scene (`state_at`'s JSON)."""
        return [self._state(i) for i in range(len(self._raw))]

    def _state(self, index: int) -> dict[str, Any]:
        ego_row, actor_rows, lights, events, score, termination = self._raw[index]
        ego, actors = ego_row.tolist(), actor_rows.tolist()
        return {
            "time_s": self.times[index],
            "ego": {
                "x": ego[0],
                "y": ego[1],
                "yaw": ego[2],
                "speed_mps": ego[3],
                "length_m": ego[4],
                "width_m": ego[5],
            },
            "actors": [
                {
                    "id": int(r[0]),
                    "x": r[1],
                    "y": r[2],
                    "yaw": r[3],
                    "speed_mps": r[4],
                    "length_m": r[5],
                    "width_m": r[6],
                    "traffic": bool(r[7]),
                }
                for r in actors
            ],
            "lights": [{"tl_id": t, "lane": lane, "color": c} for t, lane, c in lights],
            "events": events,
            "score": score,
            "termination": termination,
        }

    def _step(self) -> None:
        action = self._agent.act(self._obs, self._info)
        self._obs, _, terminated, truncated, self._info = self.env.step(action)
        self.live_index += 1
        if self.live_index == len(self._raw):
            self._record()
            if terminated or truncated:
                self.done = True
                self.score = self.env.sim.score()
                self.release_world()

    def _index_at(self, t: float) -> int:
        """The last decision at or before t (the first when t precedes it)."""
        i = bisect.bisect_right(self.times, t + 1e-9) - 1
        return max(i, 0)

    def _extend_to(self, t: float) -> None:
        """Drives on until the recorded states reach t (or the episode ends)."""
        if self.done or self.times[-1] >= t - 1e-9:
            return
        if self.env is None:
            self._open_world()
        while not self.done and self.times[-1] < t - 1e-9:
            self._step()

    @_locked
    def state_at(self, t: float) -> dict[str, Any]:
        self._extend_to(t)
        return self._state(self._index_at(t))

    @_locked
    def frame_at(self, t: float, view: str) -> np.ndarray:
        """The front camera ("front") or BEV ("bev") of the world at the decision at/before t."""
        self._extend_to(t)
        return self._render(self._index_at(t), view)

    def _render(self, index: int, view: str) -> np.ndarray:
        snap = self.snapshots[index]
        if view == "front":
            return snap.render_camera(FRONT)
        if view == "bev":
            return snap.render_bev(BEV)
        raise ValueError(f"view {view!r}: expected 'front' or 'bev'")

    @_locked
    def png_at(self, t: float, view: str) -> tuple[bytes, float]:
        """`frame_at` as PNG (cached per decision) and the decision's time."""
        self._extend_to(t)
        index = self._index_at(t)
        self.focus = index
        key = (index, view)
        if key not in self.frames:
            self.frames[key] = png_bytes(self._render(index, view))
        return self.frames[key], self.times[index]

    @_locked
    def precompute_step(self) -> bool:
        """One unit of work ahead of the page (False: nothing left): first the whole episode's
        states (so the scene at any t is a lookup), then one frame, the nearest unrendered
        decision at or after the focus first."""
        if not self.done:
            self._extend_to(self.times[-1] + 5.0)
            return True
        n = len(self._raw)
        for index in [*range(self.focus, n), *range(0, self.focus)]:
            for view in ("front", "bev"):
                if (index, view) not in self.frames:
                    self.frames[(index, view)] = png_bytes(self._render(index, view))
                    return True
        return False

    @_locked
    def episode(self) -> dict[str, Any]:
        """Drives the episode to its end: its first and last decision times and how it ended."""
        self._extend_to(float("inf"))
        assert self.score is not None
        return {
            "driver": self.driver,
            "start_s": self.times[0],
            "end_s": self.times[-1],
            "termination": self.score["termination_reason"],
            "score": self.score["score_composed"],
        }

    @_locked
    def run_to_end(self) -> dict[str, Any]:
        """Drives the episode to its end; the playback (every decision's state) and the score."""
        self._extend_to(float("inf"))
        return {"driver": self.driver, "states": self.states, "score": self.score}


class PlayerCache:
    """Players by (path, text, seed, driver), least recently used first out."""

    def __init__(self, size: int = 4) -> None:
        self.size = size
        self._players: OrderedDict[tuple[str, str | None, int, str], ScenePlayer] = OrderedDict()
        self._lock = threading.Lock()

    def most_recent(self) -> ScenePlayer | None:
        with self._lock:
            return next(reversed(self._players.values()), None)

    def get(self, path: str, text: str | None, seed: int = 0, driver: str = "expert") -> ScenePlayer:
        key = (path, text, seed, driver)
        old: list[ScenePlayer] = []
        with self._lock:
            player = self._players.get(key)
            if player is None:
                self._release_worlds(list(self._players.values()))
                player = ScenePlayer(path, text, seed=seed, driver=driver)
                self._players[key] = player
                while len(self._players) > self.size:
                    old.append(self._players.popitem(last=False)[1])
            self._players.move_to_end(key)
        for p in old:
            p.close()  # waits for a request or the precompute thread still using it
        return player

    def release_worlds(self) -> None:
        """Closes the live worlds of players no thread is using: a new buffer then gets the
        process's in-process SUMO (another, as a TraCI subprocess, is slower to start and step)."""
        with self._lock:
            players = list(self._players.values())
        self._release_worlds(players)

    @staticmethod
    def _release_worlds(players: list[ScenePlayer]) -> None:
        for p in players:
            if p.lock.acquire(blocking=False):
                try:
                    p.release_world()
                finally:
                    p.lock.release()

    def close(self) -> None:
        with self._lock:
            players = list(self._players.values())
            self._players.clear()
        for p in players:
            p.close()


def preview_frames(path: str, time_s: float, *, seed: int = 0, text: str | None = None) -> dict[str, bytes]:
    """Front and BEV PNGs of the scene at `time_s` driven by the expert (`scenario preview --time`)."""
    player = ScenePlayer(path, text, seed=seed)
    try:
        return {view: png_bytes(player.frame_at(time_s, view)) for view in ("front", "bev")}
    finally:
        player.close()
