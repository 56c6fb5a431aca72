"""Python clients of the estimation pipeline's shared-memory contract (docs/wire.md)."""

from .slot_log import read_slots
from .wire import *  # noqa: F401,F403
