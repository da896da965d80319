"""Gymnasium environments."""

from drivehierarchy.envs.config import BevConfig, CameraConfig, R4Config

__all__ = ["BevConfig", "CameraConfig", "R4Config"]
