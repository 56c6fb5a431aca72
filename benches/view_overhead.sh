#!/usr/bin/env bash
# The live view's cost to the loop (docs/view.md, "Cost to the loop"): `demo` without a view
# and `demo --view` with a connected page (a websocket reader that takes every frame),
# interleaved, ROUNDS rounds of each; prints every run's end-to-end p50/p99 from report.json
# and the ratio of the medians of the p50s.
#
#   benches/view_overhead.sh [ROUNDS] [STEPS] [RATE]     # defaults 7 5000 1000
#   IPC_RUNNER=target/release/pipeline-node benches/view_overhead.sh
set -euo pipefail
cd "$(dirname "$0")/.."
export IOX2_LOG_LEVEL=Error
rounds=${1:-7} steps=${2:-5000} rate=${3:-1000}
# IPC_RUNNER: an executable with the view already built (the tests' target/release/pipeline-node).
bin=${IPC_RUNNER:-}
if [ -z "$bin" ]; then
    cargo build --release -p ipc-runner --features view --quiet
    bin=target/release/ipc-runner
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# A page that reads everything: the websocket handshake, then every byte until the server
# closes (the frames themselves are not parsed).
reader='
import socket, sys
host, port = sys.argv[1].rsplit(":", 1)
s = socket.create_connection((host, int(port)))
s.sendall(b"GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
          b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n")
n = 0
while True:
    b = s.recv(65536)
    if not b:
        break
    n += len(b)
print(n)
'

p50() { python3 -c 'import json,sys; l=json.load(open(sys.argv[1]))["latency"]["end_to_end"]; print(l["p50_us"], l["p99_us"])' "$1"; }

echo "round mode p50_us p99_us page_bytes"
for r in $(seq 1 "$rounds"); do
    for mode in off on; do
        out="$work/$r-$mode"
        args=(demo --steps "$steps" --rate "$rate" --quiet --out "$out" --prefix "viewbench-$$-$r-$mode")
        if [ "$mode" = on ]; then
            "$bin" "${args[@]}" --view --view-addr 127.0.0.1:0 --view-linger 1 >"$out.log" 2>"$out.err" &
            pid=$!
            until grep -q '^view: http://' "$out.err" 2>/dev/null; do sleep 0.02; done
            addr=$(grep -m1 '^view: http://' "$out.err" | sed 's#view: http://##; s#/$##')
            python3 -c "$reader" "$addr" >"$out.bytes" &
            rpid=$!
            wait "$pid"
            kill "$rpid" 2>/dev/null || true
            wait "$rpid" 2>/dev/null || true
            bytes=$(cat "$out.bytes" 2>/dev/null || echo "?")
        else
            "$bin" "${args[@]}" >"$out.log" 2>"$out.err"
            bytes=-
        fi
        echo "$r $mode $(p50 "$out/report.json") $bytes"
    done
done | tee "$work/table"
python3 - "$work/table" <<'PY'
import statistics, sys
rows = [l.split() for l in open(sys.argv[1]) if l[0].isdigit()]
off = [float(r[2]) for r in rows if r[1] == "off"]
on = [float(r[2]) for r in rows if r[1] == "on"]
m_off, m_on = statistics.median(off), statistics.median(on)
print(f"median p50: without a view {m_off:.2f} µs, with a connected page {m_on:.2f} µs, ratio {m_on / m_off:.3f}")
PY
