"""The interactive scenario editor (`drivehierarchy editor`): a local web page over `_core`."""

from drivehierarchy.editor.app import create_app

__all__ = ["create_app"]
