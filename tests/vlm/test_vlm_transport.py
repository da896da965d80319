"""The async transport (openai SDK) against the real loopback server: health check, decoding,
retries, typed failures, many requests in flight over one pool, and the scripted R4 driver."""

from __future__ import annotations

import asyncio
import socket
import threading
from typing import Any

import pytest

from drivehierarchy.agents.vlm.agent import CLOSED_LOOP_DECODING, VLMDriver, VLMOptions
from drivehierarchy.agents.vlm.transport import AsyncChatTransport, ServerUnavailable
from drivehierarchy.testing.openai_server import (
    ChatRequest,
    Fault,
    ScriptedOpenAIServer,
    route_driver,
    route_points,
)

MSGS = [{"role": "user", "content": [{"type": "text", "text": "hi"}]}]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_health_check_names_the_problem() -> None:
    async def go(url: str, model: str, **kw) -> list[str]:
        t = AsyncChatTransport(url, model, **kw)
        try:
            return await t.health_check()
        finally:
            await t.aclose()

    with ScriptedOpenAIServer(models=("a", "b")) as url:
        assert asyncio.run(go(url, "b")) == ["a", "b"]
        with pytest.raises(ServerUnavailable, match=r"--model .c.: not served at .*it serves: a, b"):
            asyncio.run(go(url, "c"))
    with ScriptedOpenAIServer(api_key="k") as url, pytest.raises(ServerUnavailable, match="HTTP 401"):
        asyncio.run(go(url, "test-model", api_key="wrong"))
    with pytest.raises(ServerUnavailable, match="no OpenAI-compatible server answers"):
        asyncio.run(go(f"http://127.0.0.1:{_free_port()}/v1", "m"))


def test_closed_loop_decoding_is_explicit_and_sent() -> None:
    server = ScriptedOpenAIServer(lambda r: "steer: 0\ntarget_speed_mps: 3")
    server.keep_log = True
    with server as url:
        driver = VLMDriver(VLMOptions(base_url=url, model="test-model"))

        async def go():
            try:
                return await driver.request(MSGS)
            finally:
                await driver.transport.aclose()

        reply = asyncio.run(go())
    assert reply.raw == "steer: 0\ntarget_speed_mps: 3" and reply.error is None and reply.attempts == 1
    body = server.requests_log[0].body
    assert body["temperature"] == 0.0 and body["top_p"] == 1.0 and body["seed"] == 0
    assert body["max_tokens"] == CLOSED_LOOP_DECODING.max_tokens == 256
    assert "repetition_penalty" not in body  # neutral default, not sent (strict servers reject it)


def test_transport_failures_become_no_reply_with_the_kind() -> None:
    with ScriptedOpenAIServer(lambda r: Fault.http(503)) as url:
        driver = VLMDriver(VLMOptions(base_url=url, model="test-model", max_retries=2, backoff_s=0.001))

        async def go():
            try:
                return await driver.request(MSGS)
            finally:
                await driver.transport.aclose()

        reply = asyncio.run(go())
    assert reply.raw is None and reply.error == "http_error" and reply.attempts == 3
    assert "HTTP 503" in (reply.error_detail or "")


def test_many_requests_in_flight_over_one_pool() -> None:
    # The server answers nobody until 16 requests are open at once (a barrier in its handler
    # threads), so this passes only if one transport really keeps 16 in flight; no clock involved
    # (a serial client breaks the barrier at its timeout and gets errors).
    barrier = threading.Barrier(16, timeout=60)

    def policy(_req: ChatRequest) -> str:
        barrier.wait()  # 32 requests: two rounds of 16
        return "ok"

    server = ScriptedOpenAIServer(policy)
    with server as url:

        async def go() -> list[Any]:
            t = AsyncChatTransport(url, "test-model", timeout_s=120.0)
            try:
                return await asyncio.gather(*(t.complete(MSGS) for _ in range(32)))
            finally:
                await t.aclose()

        outs = asyncio.run(go())
    assert not barrier.broken
    assert all(o.text == "ok" for o in outs)
    assert server.stats.max_in_flight >= 16


def test_route_driver_follows_the_prompt_route() -> None:
    from drivehierarchy.testing.openai_server import parse_chat_request

    def ask(points: str) -> str:
        text = (
            "Q(frame 1): The ego vehicle is driving at the speed of 4.0 m/s, and it wants to follow "
            "the road. The local future route in ego coordinates is given as (forward_m, right_m): "
            f"[{points}]. Your ..."
        )
        body = {"messages": [{"role": "user", "content": [{"type": "text", "text": text}]}]}
        return route_driver(parse_chat_request(body))

    assert route_points("(forward_m, right_m): [(5.0, -1.0), (10.0, 2.5)]. x") == [(5.0, -1.0), (10.0, 2.5)]
    straight = ask("(5.0, 0.0), (10.0, 0.0), (15.0, 0.0)")
    right = ask("(5.0, 1.0), (10.0, 4.0), (15.0, 9.0)")
    left = ask("(5.0, -1.0), (10.0, -4.0), (15.0, -9.0)")
    assert straight == "steer: 0.000\ntarget_speed_mps: 8.0"
    steer = {k: float(v.split("\n")[0].split(": ")[1]) for k, v in [("r", right), ("l", left)]}
    assert steer["r"] > 0.1 and steer["l"] == -steer["r"]
    assert ask("") == "steer: 0.0\ntarget_speed_mps: 0.0"
