"""Sensor publisher example: publishes the slots of a slot log (docs/replay.md) to ipc-runner.

    ipc-runner stream-header --scenario linear > out/header.json
    python3 publish_slots.py --prefix mine --header out/header.json --slots slots.csv --rate 1000

The log is read as `ipc-runner replay` reads it (estpipe.read_slots, rule for rule), so the
runner's estimates equal replay's: a delivered row goes out with its measurement, a row with
delivered = 0 as a channel dropout, and a row flagged lost (FLAG_IPC_LOST, or FLAG_NET_LOST
undelivered), a node missing from an instant or a missing instant is *not sent*: the gap in
the node's seq is the runner's lost slot (docs/wire.md, Stream rules). Rows replay refuses
are refused here too, with the file, line and field, before anything is sent (exit code 2).

Every slot carries the stream header (the shape and model fingerprint the runner checks); the
slots of an instant go out in node order, then one notification on <prefix>/slots-ready; each
node's END marker (k = the log's last instant) closes the stream. Each slot is sent until
every subscriber has it (estpipe.send_slot: iceoryx2 0.10 discards a slot for a runner that
has not yet connected to this publisher), so nothing is lost at any rate.
"""

import argparse
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
    p.add_argument("--connect-timeout", type=float, default=30.0,
                   help="seconds to wait for a runner on <prefix>/slots (0 = for ever); "
                        "as channel-sim's, the runner being the side started first")
    return p.parse_args()


def wait_for_subscriber(node, service, prefix, timeout):
    """Slots sent before a subscriber exists are lost: wait for the runner. False when none
    came within `timeout` seconds (0: waits for ever)."""
    if service.dynamic_config.number_of_subscribers > 0:
        return True
    print(f"publish_slots.py: waiting for a runner on {prefix}/slots"
          + (f" (up to {timeout:g} s)" if timeout > 0 else ""), file=sys.stderr, flush=True)
    start = estpipe.monotonic_ns()
    while service.dynamic_config.number_of_subscribers == 0:
        if timeout > 0 and (estpipe.monotonic_ns() - start) / 1e9 > timeout:
            return False
        node.wait(iox2.Duration.from_millis(20))
    return True


def main() -> int:
    args = parse_args()
    if not (args.rate >= 0 and args.rate <= 1e6):
        print(f"publish_slots.py: error: --rate {args.rate} is not in [0, 1e6]", file=sys.stderr)
        return 2
    if not (args.connect_timeout >= 0 and args.connect_timeout < 1e9):
        print(f"publish_slots.py: error: --connect-timeout {args.connect_timeout} is not a "
              f"number of seconds >= 0 (0 = for ever)", file=sys.stderr)
        return 2
    try:
        with open(args.header) as f:
            header = estpipe.StreamHeader.from_json(json.load(f))
        nodes, ny = header.nodes, list(header.ny)
        late = []
        instants = estpipe.read_slots(args.slots, nodes, ny, late=late)
    except (OSError, ValueError) as e:
        print(f"publish_slots.py: error: {args.header if isinstance(e, OSError) else ''}"
              f"{e}", file=sys.stderr)
        return 2

    if late:
        # The log's late slots (late_after > 0): the runner folded them into their instants
        # with --lag; a publisher can only send a slot in its node's order, so they go out as
        # lost, as replay steps them before its fold (`replay --lag L` folds them in).
        print(f"publish_slots.py: {len(late)} late slot(s) in the log are published as lost "
              f"(their lateness cannot be replayed over the wire; `ipc-runner replay --lag L` "
              f"folds them in)", file=sys.stderr)
    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    try:
        node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
        service = estpipe.slot_service(node, args.prefix)
        publisher = (
            service.publisher_builder()
            .backpressure_strategy(iox2.BackpressureStrategy.RetryUntilDelivered)
            .create()
        )
        notifier = estpipe.ready_event_service(node, args.prefix).notifier_builder().create()
    except Exception as e:  # iceoryx2 raises one exception type per builder and cause
        print(f"publish_slots.py: error: cannot publish on {args.prefix}/slots "
              f"({type(e).__name__}: {e}): the service exists with another QoS, or --prefix "
              f"is not a valid service name (docs/wire.md, Services and QoS)",
              file=sys.stderr)
        return 1
    ready = iox2.EventId.new(estpipe.READY_EVENT)

    try:
        connected = wait_for_subscriber(node, service, args.prefix, args.connect_timeout)
    except (iox2.NodeWaitFailure, KeyboardInterrupt):
        print("publish_slots.py: stopped while waiting for a runner", file=sys.stderr)
        return 130
    if not connected:
        print(f"publish_slots.py: error: no runner on {args.prefix}/slots within "
              f"{args.connect_timeout:g} s: start `ipc-runner run --prefix {args.prefix} ...` "
              f"first, or give --connect-timeout 0 to wait for ever", file=sys.stderr)
        return 3
    stream_id = (os.getpid() << 32) ^ estpipe.monotonic_ns()
    period_ns = round(1e9 / args.rate) if args.rate > 0 else 0
    t0 = estpipe.monotonic_ns()
    # Per node, the last instant of its stream: its END/ABORT marker's k and seq (since wire
    # version 3). A lost slot is not sent but still counts: the marker's k covers it.
    last_sent = [0] * nodes
    sent = lost = again = 0
    try:
        for i, (k, obs) in enumerate(instants):
            if period_ns:
                due = t0 + i * period_ns
                now = estpipe.monotonic_ns()
                if due > now:
                    node.wait(iox2.Duration.from_nanos(due - now))
            for m, (state, flags, y, tokens) in enumerate(obs):
                last_sent[m] = k
                if state == estpipe.LOST:
                    lost += 1
                    continue
                delivered = state == estpipe.DELIVERED
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
                    # Never on the wire (docs/wire.md, Constants): a delivered row's
                    # measurement is used whatever its flags, as replay uses it.
                    flags=(flags & ~(estpipe.FLAG_IPC_LOST | estpipe.FLAG_NET_LOST | estpipe.FLAG_TOKENS))
                    | (estpipe.FLAG_TOKENS if delivered and tokens is not None else 0),
                    tokens=tokens if delivered and tokens is not None else 0,
                    period_ns=period_ns,
                    stream_start_ns=t0,
                )
                slot.y[:] = y
                slot.send_ns = estpipe.monotonic_ns()
                again += estpipe.send_slot(publisher, service, header, slot)
                sent += 1
            notifier.notify_with_custom_event_id(ready)
        kind = estpipe.SLOT_END
    except (iox2.NodeWaitFailure, KeyboardInterrupt):
        kind = estpipe.SLOT_ABORT
    except estpipe.NotDelivered as e:
        print(f"publish_slots.py: error: {e}", file=sys.stderr)
        return 1
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
        try:
            estpipe.send_slot(publisher, service, header, end)
        except estpipe.NotDelivered as e:
            print(f"publish_slots.py: {e} (END marker)", file=sys.stderr)
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
    print(f"published {sent} slots of {len(instants)} instants ({lost} lost slots not sent, "
          f"{again} sent again)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
