"""The VLM driver: one user turn per decision sent to any OpenAI-compatible server.

`payload` builds the protocol's message (docs/protocol.md#r4-loop), `transport` sends it (the `openai` SDK),
the env parses the raw reply in Rust (docs/protocol.md#r4-actuation). `presets` names the paper's
15 models."""

from drivehierarchy.agents.vlm.agent import VLMAgent, VLMOptions
from drivehierarchy.agents.vlm.payload import PayloadOptions, build_messages
from drivehierarchy.agents.vlm.presets import PRESETS, ModelPreset, resolve_model

__all__ = [
    "PRESETS",
    "ModelPreset",
    "PayloadOptions",
    "VLMAgent",
    "VLMOptions",
    "build_messages",
    "resolve_model",
]
