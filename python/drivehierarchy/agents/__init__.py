"""Driving agents: the protocol (`base`), the privileged expert (`expert`) and the VLM driver
over any OpenAI-compatible server (`vlm`)."""
