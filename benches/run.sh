#!/usr/bin/env bash
# Regenerates BENCHMARKS.md at the workspace root: builds the benchmark binaries and
# ipc-runner in release mode, then runs every part (criterion, callgrind instruction counts,
# Cortex-M4 counts from .ci/firmware, IPC latency, the pipeline end to end, Monte-Carlo
# throughput) and writes the tables.
#
#   benches/run.sh                 # full run (~15-25 min on 2 cores)
#   benches/run.sh --quick         # short runs, indicative only
#   benches/run.sh --skip firmware,eval
#
# Needs valgrind (apt-get install valgrind); the firmware part needs what .ci/firmware needs
# (qemu-system-arm, the thumbv7em-none-eabihf target) and is reported as not run otherwise.
set -euo pipefail
cd "$(dirname "$0")/.."
export IOX2_LOG_LEVEL=Error
cargo build --release -p benches --bins
cargo build --release -p ipc-runner
exec target/release/report "$@"
