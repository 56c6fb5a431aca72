"""Sensor publisher example: publishes the slots of a slot log (docs/replay.md) to ipc-runner.

    ipc-runner stream-header --scenario linear > header.json
    python3 publish_slots.py --prefix mine --header header.json --slots slots.csv --rate 1000

Every slot carries the stream header (the shape and model fingerprint the runner checks); the
slots of an instant go out in node order with dense sequence numbers, then one notification
on <prefix>/slots-ready; an END marker closes the stream. A full runner queue blocks the send
(iceoryx2 RetryUntilDelivered), so nothing is lost.
"""

import argparse
import ctypes
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import iceoryx2 as iox2  # noqa: E402

import estpipe  # noqa: E402


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--prefix", default=estpipe.DEFAULT_PREFIX)
    p.add_argument("--header", required=True, help="JSON from `ipc-runner stream-header`")
    p.add_argument("--slots", required=True, help="slot log CSV (docs/replay.md)")
    p.add_argument("--rate", type=float, default=0.0, help="instants per second; 0 = at once")
    p.add_argument("--connect-timeout", type=float, default=30.0)
    return p.parse_args()


def wait_for_subscriber(node, service, timeout):
    """Slots sent before a subscriber exists are lost: wait for the runner."""
    start = estpipe.monotonic_ns()
    while service.dynamic_config.number_of_subscribers == 0:
        if (estpipe.monotonic_ns() - start) / 1e9 > timeout:
            raise TimeoutError("no runner subscribed within the connect timeout")
        node.wait(iox2.Duration.from_millis(2))


def send(publisher, header, slot):
    sample = publisher.loan_uninit()
    ctypes.memmove(sample.user_header_ptr, ctypes.byref(header), ctypes.sizeof(header))
    sample.write_payload(slot).send()


def main() -> int:
    args = parse_args()
    with open(args.header) as f:
        header = estpipe.StreamHeader.from_json(json.load(f))
    nodes, ny = header.nodes, list(header.ny)
    instants = estpipe.read_slots(args.slots, nodes, ny)

    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    service = estpipe.slot_service(node, args.prefix)
    publisher = (
        service.publisher_builder()
        .backpressure_strategy(iox2.BackpressureStrategy.RetryUntilDelivered)
        .create()
    )
    notifier = estpipe.ready_event_service(node, args.prefix).notifier_builder().create()
    ready = iox2.EventId.new(estpipe.READY_EVENT)

    wait_for_subscriber(node, service, args.connect_timeout)
    stream_id = (os.getpid() << 32) ^ estpipe.monotonic_ns()
    period_ns = round(1e9 / args.rate) if args.rate > 0 else 0
    t0 = estpipe.monotonic_ns()
    # Per node, the last instant sent: its END/ABORT marker's k and seq (since wire version 3).
    last_sent = [0] * nodes
    sent = 0
    try:
        for i, (k, obs) in enumerate(instants):
            if period_ns:
                due = t0 + i * period_ns
                now = estpipe.monotonic_ns()
                if due > now:
                    node.wait(iox2.Duration.from_nanos(due - now))
            for m, (delivered, flags, y) in enumerate(obs):
                slot = estpipe.Slot(
                    version=estpipe.WIRE_VERSION,
                    kind=estpipe.SLOT_DATA,
                    stream_id=stream_id,
                    seq=estpipe.seq_of(k),
                    k=k,
                    node=m,
                    nodes=nodes,
                    ny=ny[m],
                    delivered=int(delivered),
                    flags=flags,
                    period_ns=period_ns,
                    stream_start_ns=t0,
                )
                slot.y[:] = y
                slot.send_ns = estpipe.monotonic_ns()
                send(publisher, header, slot)
                last_sent[m] = k
                sent += 1
            notifier.notify_with_custom_event_id(ready)
        kind = estpipe.SLOT_END
    except iox2.NodeWaitFailure:
        kind = estpipe.SLOT_ABORT
    # Every node's stream ends with its own marker (seq = k = its last instant sent).
    for m in range(nodes):
        end = estpipe.Slot(
            version=estpipe.WIRE_VERSION,
            kind=kind,
            stream_id=stream_id,
            seq=last_sent[m],
            k=last_sent[m],
            node=m,
            nodes=nodes,
            period_ns=period_ns,
            stream_start_ns=t0,
            send_ns=estpipe.monotonic_ns(),
        )
        send(publisher, header, end)
    notifier.notify_with_custom_event_id(ready)
    # The runner reads the tail from our data segment: stay until it has detached.
    start = estpipe.monotonic_ns()
    while service.dynamic_config.number_of_subscribers > 0:
        if estpipe.monotonic_ns() - start > 5e9:
            break
        try:
            node.wait(iox2.Duration.from_millis(2))
        except iox2.NodeWaitFailure:
            break
    print(f"published {sent} slots of {len(instants)} instants", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
