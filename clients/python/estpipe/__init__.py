"""Python clients of the estimation pipeline's shared-memory contract (docs/wire.md)."""

from .publish import NotDelivered, send_slot
from .slot_log import DELIVERED, DROPPED, LOST, read_slots
from .wire import *  # noqa: F401,F403
