"""History and memory in the decision message (docs/vlm.md#history-and-memory): the exact content array of
every mode, the episode-start rule, the controls, the ego and memory texts, no re-encoding, and
what the manifest and the run's identity record."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivehierarchy import ConfigError
from drivehierarchy.agents.vlm import PayloadOptions, VLMOptions, build_messages
from drivehierarchy.agents.vlm import payload as payload_mod
from drivehierarchy.agents.vlm.history import DecisionHistory, HistoryOptions
from drivehierarchy.benchmark.r4 import runner

TICK_S = 0.05
FRONT = "({w}x{h}, looking forward from the ego vehicle's roof, 100 degree field of view):"
BEV = "({s}x{s}, top-down, ego vehicle at the centre facing up, local route drawn in red):"


def _obs(n: int) -> dict:
    """Decision n's observation: small frames whose colour names the decision."""
    front = np.full((6, 10, 3), 10 * n, dtype=np.uint8)
    bev = np.full((8, 8, 3), 200 - 10 * n, dtype=np.uint8)
    return {"front": front, "bev": bev, "prompt": f"prompt {n}."}


def _url(n: int, key: str) -> str:
    return payload_mod.jpeg_data_url(_obs(n)[key])


URLS = {_url(n, k): f"{k}{n}" for n in range(1, 12) for k in ("front", "bev")}


def _drive(
    opts: HistoryOptions, decisions: int, payload: PayloadOptions | None = None, seed: int = 0
) -> list:
    """The content arrays of decisions 1..`decisions`, asked every 5 ticks from tick 4, images
    replaced by the frame they carry (`front3` = decision 3's front frame)."""
    h = DecisionHistory(opts, payload or PayloadOptions(), TICK_S, seed)
    out = []
    for n in range(1, decisions + 1):
        tick = 4 + 5 * (n - 1)
        ego = (2.0 * n, 0.0, 0.0, float(n))  # along +x at 2 m per decision, heading +x
        (msg,) = h.messages(_obs(n), n, tick, ego)
        assert msg["role"] == "user"
        out.append(
            [
                ("text", p["text"]) if p["type"] == "text" else ("image", URLS[p["image_url"]["url"]])
                for p in msg["content"]
            ]
        )
        h.record_reply(n, {"parsed": {"steer": 0.1, "target_speed_mps": 5.0}, "failure": None})
    return out


def _front(when: str | None = None) -> str:
    head = "Front camera image" + (f" at {when}" if when else "")
    return f"{head} {FRONT.format(w=10, h=6)}"


def _bev(when: str | None = None) -> str:
    head = "Bird's-eye view image" + (f" at {when}" if when else "")
    return f"{head} {BEV.format(s=8)}"


NOW = "t-0.00 s, the current frame"


def test_without_flags_the_message_is_the_papers() -> None:
    (msg,) = build_messages(_obs(3), 3)
    content = [(p["type"], p.get("text") or URLS[p["image_url"]["url"]]) for p in msg["content"]]
    assert content == [
        ("text", _front()),
        ("image_url", "front3"),
        ("text", _bev()),
        ("image_url", "bev3"),
        ("text", "Q(frame 3): prompt 3."),
    ]
    assert not HistoryOptions().enabled


def test_history_frames_with_bev_exact_content_and_episode_start() -> None:
    msgs = _drive(HistoryOptions(frames=2, bev=True), 4)
    # Decision 1: nothing before it, so only the current frames (labelled now).
    assert msgs[0] == [
        ("text", _front(NOW)),
        ("image", "front1"),
        ("text", _bev(NOW)),
        ("image", "bev1"),
        ("text", "Q(frame 1): prompt 1."),
    ]
    assert [k for k, _ in msgs[1]].count("image") == 4  # one past frame pair, then the current
    assert msgs[3] == [
        ("text", _front("t-0.50 s")),
        ("image", "front2"),
        ("text", _bev("t-0.50 s")),
        ("image", "bev2"),
        ("text", _front("t-0.25 s")),
        ("image", "front3"),
        ("text", _bev("t-0.25 s")),
        ("image", "bev3"),
        ("text", _front(NOW)),
        ("image", "front4"),
        ("text", _bev(NOW)),
        ("image", "bev4"),
        ("text", "Q(frame 4): prompt 4."),
    ]


def test_stride_spaces_the_frames_and_the_message_grows_to_its_full_size() -> None:
    msgs = _drive(HistoryOptions(frames=3, stride=2), 7)
    past = [
        [v for k, v in m if k == "image" and v.startswith("front") and v != f"front{i}"]
        for i, m in enumerate(msgs, 1)
    ]
    assert past == [
        [],
        [],
        ["front1"],
        ["front2"],
        ["front1", "front3"],
        ["front2", "front4"],
        ["front1", "front3", "front5"],
    ]
    assert msgs[6][:6] == [
        ("text", _front("t-1.50 s")),
        ("image", "front1"),
        ("text", _front("t-1.00 s")),
        ("image", "front3"),
        ("text", _front("t-0.50 s")),
        ("image", "front5"),
    ]
    # Without --history-bev the current BEV is still sent, labelled now.
    assert msgs[6][6:] == [
        ("text", _front(NOW)),
        ("image", "front7"),
        ("text", _bev(NOW)),
        ("image", "bev7"),
        ("text", "Q(frame 7): prompt 7."),
    ]


def test_ego_history_and_memory_texts_exact() -> None:
    msgs = _drive(HistoryOptions(ego=2, memory=2), 4)
    ego_head = "Ego history, oldest first, positions in the current ego frame as (forward_m, right_m)"
    mem_head = "Your previous decisions, oldest first"
    # No past frames: the paper's descriptors, then the two texts, then the question.
    assert msgs[0] == [
        ("text", _front()),
        ("image", "front1"),
        ("text", _bev()),
        ("image", "bev1"),
        ("text", f"{ego_head}: none yet (the episode has just started)."),
        ("text", f"{mem_head}: none yet (this is the first decision)."),
        ("text", "Q(frame 1): prompt 1."),
    ]
    assert msgs[3][4:] == [
        ("text", f"{ego_head}: t-0.50 s: (-4.0, 0.0) at 2.0 m/s; t-0.25 s: (-2.0, 0.0) at 3.0 m/s."),
        (
            "text",
            f"{mem_head}: t-0.50 s (frame 2): steer: 0.1, target_speed_mps: 5.0; "
            "t-0.25 s (frame 3): steer: 0.1, target_speed_mps: 5.0.",
        ),
        ("text", "Q(frame 4): prompt 4."),
    ]


def test_ego_positions_are_in_the_current_ego_frame() -> None:
    h = DecisionHistory(HistoryOptions(ego=1), PayloadOptions(blind=True), TICK_S)
    h.messages(_obs(1), 1, 4, (0.0, 0.0, 0.0, 5.0))
    # Now at (10, 5) heading +y (yaw 90°): the old position is 5 m behind and 10 m to the left.
    (msg,) = h.messages(_obs(2), 2, 9, (10.0, 5.0, math.pi / 2, 6.0))
    assert msg["content"][0]["text"].endswith(": t-0.25 s: (-5.0, -10.0) at 5.0 m/s.")


def test_memory_says_what_happened_to_each_reply() -> None:
    h = DecisionHistory(HistoryOptions(memory=3), PayloadOptions(blind=True), TICK_S)
    replies = [
        {"parsed": {"steer": -0.25, "target_speed_mps": 7.5}, "failure": None},
        {"parsed": None, "failure": "missing_both"},
        {"parsed": None, "failure": "no_reply"},
    ]
    for n, rep in enumerate(replies, 1):
        h.messages(_obs(n), n, 4 + 5 * (n - 1), None)
        h.record_reply(n, rep)
    (msg,) = h.messages(_obs(4), 4, 19, None)
    assert msg["content"][0]["text"] == (
        "Your previous decisions, oldest first: t-0.75 s (frame 1): steer: -0.25, target_speed_mps: 7.5; "
        "t-0.50 s (frame 2): unparseable reply, the previous control was held; "
        "t-0.25 s (frame 3): no reply, the previous control was held."
    )


def test_offsets_are_the_true_ones_when_decisions_are_not_evenly_spaced() -> None:
    h = DecisionHistory(HistoryOptions(frames=2), PayloadOptions(no_bev=True), TICK_S)
    for n, tick in ((1, 4), (2, 13), (3, 20)):  # e.g. --latency-aware: held ticks between decisions
        (msg,) = h.messages(_obs(n), n, tick, None)
    texts = [p["text"] for p in msg["content"] if p["type"] == "text"]
    assert texts[:2] == [_front("t-0.80 s"), _front("t-0.35 s")]
    assert h.last_offsets_s == [0.8, 0.35]


def test_shuffle_permutes_frames_under_fixed_labels_reproducibly() -> None:
    opts = HistoryOptions(frames=3, shuffle=True)
    a, b = _drive(opts, 8, seed=7), _drive(opts, 8, seed=7)
    assert a == b, "the permutation comes from the seed and the decision"
    plain = _drive(HistoryOptions(frames=3), 8)
    for n in (3, 4, 5, 6, 7, 8):  # ≥ 2 past frames: never the chronological order
        frames = [v for k, v in a[n - 1] if k == "image"]
        chrono = [v for k, v in plain[n - 1] if k == "image"]
        assert frames != chrono and sorted(frames[:-2]) == sorted(chrono[:-2]), n
        assert frames[-2:] == [f"front{n}", f"bev{n}"], "the current frames stay last"
        # Labels stay in chronological slots.
        assert [t for k, t in a[n - 1] if k == "text"] == [t for k, t in plain[n - 1] if k == "text"]
    assert a != _drive(opts, 8, seed=8)


def test_freeze_fills_every_past_slot_with_the_current_frame() -> None:
    msgs = _drive(HistoryOptions(frames=3, bev=True, freeze=True), 5)
    plain = _drive(HistoryOptions(frames=3, bev=True), 5)
    assert [t for k, t in msgs[4] if k == "text"] == [t for k, t in plain[4] if k == "text"]
    assert [v for k, v in msgs[4] if k == "image"] == ["front5", "bev5"] * 4
    assert [v for k, v in msgs[0] if k == "image"] == ["front1", "bev1"]  # same start rule


def test_past_frames_are_never_re_encoded(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []
    real = payload_mod.jpeg_data_url
    monkeypatch.setattr(payload_mod, "jpeg_data_url", lambda img, q=90: calls.append(1) or real(img, q))
    msgs = _drive(HistoryOptions(frames=4, bev=True), 6)
    assert len(calls) == 2 * 6, "one front and one BEV encode per decision, whatever the history"
    assert [k for k, _ in msgs[5]].count("image") == 10


@pytest.mark.parametrize(
    ("kwargs", "payload", "match"),
    [
        ({"frames": -1}, PayloadOptions(), "--history = -1"),
        ({"frames": 2, "stride": 0}, PayloadOptions(), "--stride = 0"),
        ({"stride": 2}, PayloadOptions(), "only with --history or --ego-history"),
        ({"bev": True}, PayloadOptions(), "--history-bev"),
        ({"frames": 1, "shuffle": True}, PayloadOptions(), "needs ≥ 2 past frames"),
        ({"frames": 2, "shuffle": True, "freeze": True}, PayloadOptions(), "choose one"),
        ({"freeze": True}, PayloadOptions(), "--history-freeze"),
        ({"memory": True}, PayloadOptions(), "--memory = True"),
        ({"frames": 2}, PayloadOptions(blind=True), "--blind"),
        ({"frames": 2, "bev": True}, PayloadOptions(no_bev=True), "no BEV"),
    ],
)
def test_bad_combinations_are_clear_errors(kwargs: dict, payload: PayloadOptions, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        VLMOptions(base_url="http://x/v1", model="m", payload=payload, history=HistoryOptions(**kwargs))


def test_manifest_records_history_and_identity_only_when_used() -> None:
    plain = runner.RunOptions(agent="vlm", vlm=VLMOptions(base_url="http://x/v1", model="m"))
    assert "history" not in plain.identity()["vlm"], "runs from before history still resume"
    assert plain.vlm.manifest()["history"]["frames"] == 0
    assert plain.run_facts() == {
        "action_level": "control",
        "inputs": {
            "history": 0,
            "stride": 1,
            "history_bev": False,
            "ego_history": 0,
            "memory": 0,
            "controls": [],
        },
    }
    h = HistoryOptions(frames=4, stride=2, bev=True, ego=3, memory=2, shuffle=True)
    used = runner.RunOptions(agent="vlm", vlm=VLMOptions(base_url="http://x/v1", model="m", history=h))
    assert used.identity()["vlm"]["history"] == {
        "frames": 4, "stride": 2, "bev": True, "ego": 3, "memory": 2, "shuffle": True, "freeze": False,
    }  # fmt: skip
    assert used.run_facts()["inputs"] == {
        "history": 4, "stride": 2, "history_bev": True, "ego_history": 3, "memory": 2,
        "controls": ["history-shuffle"],
    }  # fmt: skip
    assert runner.RunOptions().run_facts()["action_level"] == "control"


def test_the_blocking_agent_sends_the_same_history() -> None:
    """`VLMAgent` (scripts, `run_episode`) builds history like the harness: past frames, ego
    states from the env, memory from the env's parse of its earlier replies."""
    from drivehierarchy.agents.base import run_episode
    from drivehierarchy.agents.vlm import VLMAgent
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env
    from drivehierarchy.testing.openai_server import ScriptedOpenAIServer, route_driver

    server = ScriptedOpenAIServer(route_driver)
    server.keep_log = True
    h = HistoryOptions(frames=2, ego=1, memory=1)
    with server as url:
        agent = VLMAgent(VLMOptions(base_url=url, model="test-model", history=h))
        env = DriveHierarchyR4Env(scenario="01_pedestrian/town01_01_midblock_crossing")
        try:
            run_episode(env, agent, seed=0, max_steps=4)
        finally:
            agent.close()
            env.close()
    reqs = server.requests_log
    assert [len(r.images) for r in reqs] == [2, 3, 4, 4]
    assert reqs[3].user_texts[0].startswith("Front camera image at t-0.50 s (")
    assert reqs[0].user_texts[-3].endswith("none yet (the episode has just started).")
    assert reqs[3].user_texts[-3].startswith("Ego history, oldest first") and " at " in reqs[3].user_texts[-3]
    assert (
        reqs[3]
        .user_texts[-2]
        .startswith("Your previous decisions, oldest first: t-0.25 s (frame 3): steer: ")
    )
    # The past front frame is the one sent as current two decisions before, byte for byte.
    assert reqs[3].images[0].sha256 == reqs[1].images[-2].sha256


def test_request_bodies_are_the_json_the_sdk_would_send() -> None:
    """`encode_body` writes data URLs in unscanned; the bytes are exactly json.dumps' (compact,
    UTF-8), with history, with text that needs escaping, and with the marker in a prompt."""
    import json

    from drivehierarchy.agents.vlm.transport import _URL_MARK, encode_body

    h = DecisionHistory(HistoryOptions(frames=3, bev=True, memory=1), PayloadOptions(), TICK_S)
    for n in range(1, 5):
        obs = {**_obs(n), "prompt": f'prompt "{n}" \\ ünïcode\n\t{_URL_MARK if n == 4 else ""}'}
        messages = h.messages(obs, n, 4 + 5 * n, None)
        body = {"model": "m", "messages": messages, "temperature": 0.0, "max_tokens": 256}
        sent = encode_body(body)
        assert sent == json.dumps(body, ensure_ascii=False, separators=(",", ":")).encode("utf-8")
        assert json.loads(sent) == body
        assert type(messages[0]["content"][1]["image_url"]["url"]) is payload_mod.DataURL


def test_cli_history_flags_are_checked(tmp_path, capsys: pytest.CaptureFixture) -> None:
    from drivehierarchy.cli import main

    scenario = "01_pedestrian/town01_01_midblock_crossing"
    base = ["r4", "run", "--scenario", scenario, "--out", str(tmp_path / "o")]
    assert main([*base, "--history", "2"]) == 2
    assert "--history: only for --agent vlm" in capsys.readouterr().err
    vlm = [*base, "--agent", "vlm", "--base-url", "http://127.0.0.1:9/v1", "--model", "m"]
    for flags, message in (
        (["--history", "1", "--history-shuffle"], "--history-shuffle with --history = 1"),
        (["--history", "2", "--blind"], "--history = 2 with --blind"),
        (["--stride", "3"], "--stride = 3: only with --history or --ego-history"),
    ):
        assert main([*vlm, *flags]) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
