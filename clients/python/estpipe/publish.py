"""Sending one slot as the contract requires of a publisher (docs/wire.md, "Sending a slot").

iceoryx2 0.10 blocks a `RetryUntilDelivered` sender on a full queue only once the subscriber
has connected to that sender, which the runner does on its next read; until then a full
queue discards the slot for that subscriber and `send()` returns how many subscribers did
receive it. So a slot is sent again until every subscriber has it (a subscriber that had it
already receives a duplicate, which the runner ignores by its `seq`), with a short pause in
between, and for at most `timeout` seconds.
"""

import ctypes
import time

# The pause before a slot goes again (the runner's next read is what it waits for).
RESEND_PAUSE_S = 50e-6


class NotDelivered(Exception):
    """A slot did not reach every subscriber within the timeout."""


def send_slot(publisher, service, header, slot, timeout: float = 10.0) -> int:
    """Sends `slot` with the user header `header` until every subscriber of `service` (the
    slot service's port factory) has it; returns how many times it went again. Raises
    `NotDelivered` after `timeout` seconds (a subscriber that never reads)."""
    deadline = time.monotonic() + timeout
    again = 0
    while True:
        sample = publisher.loan_uninit()
        ctypes.memmove(sample.user_header_ptr, ctypes.byref(header), ctypes.sizeof(header))
        received = sample.write_payload(slot).send()
        if received >= service.dynamic_config.number_of_subscribers:
            return again
        if time.monotonic() > deadline:
            raise NotDelivered(
                f"slot k = {slot.k} of node {slot.node} reached {received} of "
                f"{service.dynamic_config.number_of_subscribers} subscribers within {timeout} s"
            )
        again += 1
        time.sleep(RESEND_PAUSE_S)
