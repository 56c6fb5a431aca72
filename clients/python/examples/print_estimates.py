"""Estimate subscriber example: prints k, x̂ and P of every estimate ipc-runner publishes.

    python3 print_estimates.py --prefix mine

A subscriber that connects while the runner runs first gets the newest estimates (the
service keeps a history). With --latency it prints only the latency from each estimate's slot
being sent to its arrival here, in µs (p50, p99), when the stream goes quiet.
"""

import argparse
import ctypes
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import iceoryx2 as iox2  # noqa: E402

import estpipe  # noqa: E402


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--prefix", default=estpipe.DEFAULT_PREFIX)
    p.add_argument("--idle-exit", type=float, default=0.0,
                   help="once estimates came, exit after this many seconds without a new one "
                        "(0 = never); before the first one it waits for ever, since the "
                        "runner and its publisher may be started minutes later")
    p.add_argument("--latency", action="store_true", help="print latency percentiles only")
    p.add_argument("--csv", action="store_true",
                   help="print k,estimator,status,x_0..,p_0.. rows (exact float repr)")
    return p.parse_args()


def percentile(sorted_values, q):
    i = min(len(sorted_values) - 1, int(q * len(sorted_values)))
    return sorted_values[i]


def main() -> int:
    args = parse_args()
    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    subscriber = estpipe.estimate_service(node, args.prefix).subscriber_builder().create()
    print("ready", file=sys.stderr, flush=True)

    latencies = []
    # The idle timer starts at the first estimate: a subscriber started before its runner
    # has a publisher must not give up before anything was published.
    last = None
    try:
        while True:
            sample = subscriber.receive()
            if sample is None:
                if (args.idle_exit and last is not None
                        and (estpipe.monotonic_ns() - last) / 1e9 > args.idle_exit):
                    break
                # Short waits: a sleeping subscriber adds its wake-up to the latency.
                node.wait(iox2.Duration.from_micros(50))
                continue
            now = estpipe.monotonic_ns()
            est = estpipe.Estimate()
            ctypes.memmove(ctypes.byref(est), sample.payload_ptr, ctypes.sizeof(est))
            sample.delete()
            last = now
            if args.latency:
                latencies.append((now - est.slot_send_ns) / 1e3)
            elif args.csv:
                n = est.nx
                values = list(est.x[:n]) + list(est.p[: n * (n + 1) // 2])
                print(",".join([str(est.k), est.estimator_name(), str(est.status)]
                               + [repr(v) for v in values]))
            else:
                print(f"k {est.k:5} {est.estimator_name():8} x̂ {est.xhat()}  P {est.covariance()}")
    except (iox2.NodeWaitFailure, KeyboardInterrupt):
        pass
    if args.latency and latencies:
        latencies.sort()
        print(f"estimates {len(latencies)} p50 {percentile(latencies, 0.5):.2f} "
              f"p99 {percentile(latencies, 0.99):.2f} us")
    return 0


if __name__ == "__main__":
    sys.exit(main())
