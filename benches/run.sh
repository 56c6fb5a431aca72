#!/usr/bin/env bash
# Regenerates BENCHMARKS.md at the workspace root: builds the benchmark binaries and
# ipc-runner in release mode, then runs every part (criterion, callgrind instruction counts,
# Cortex-M4 counts from .ci/firmware, the pipeline end to end, the bridge hop against raw
# zenoh and the one-host pipeline, Monte-Carlo throughput against b7a974e and per preset) and
# writes the tables.
#
#   benches/run.sh                 # full run (~21 min on 2 cores once built; the first also
#                                  # builds two extra kf_interleaved variants and b7a974e's
#                                  # ipc-runner, a few minutes each)
#   benches/run.sh --quick         # short runs, indicative only
#   benches/run.sh --skip firmware,eval       # parts: criterion,icount,firmware,pipeline,bridge,eval-baseline,eval,view
#
# Needs valgrind (apt-get install valgrind); the firmware part needs what .ci/firmware needs
# (qemu-system-arm, the thumbv7em-none-eabihf target) and is reported as not run otherwise.
set -euo pipefail
cd "$(dirname "$0")/.."
export IOX2_LOG_LEVEL=Error
# The benchmark binaries with the profile `cargo bench` uses (`profile.bench`: thin LTO, one
# codegen unit), so that criterion, icount and kf_interleaved time the same build; the report
# builds the plain-release variants of kf_interleaved into target/plain-release and
# target/x86-64-v3 itself.
cargo build --profile bench -p benches --bins
# With the bridge: the part `bridge` runs `ipc-runner demo --via zenoh`; with the live view:
# the part `view` runs `ipc-runner demo --view`.
cargo build --release -p ipc-runner --features bridge,view
exec target/release/report "$@"
