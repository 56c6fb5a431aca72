/* The estimation pipeline's wire contract (docs/wire.md) for C: the same layouts as the Rust
 * crate estpipe-wire (`#[repr(C)]`). Every size, alignment and offset is asserted at compile
 * time below; clients/c/check_layout.c checks them again at run time and a Rust test compares
 * its output with the Rust types, so this header cannot drift from them.
 *
 * To publish or subscribe, use the C client library (estpipe.h, built by cargo: iceoryx2 0.10's
 * own C binding is not on crates.io), or iceoryx2's C binding (iox2) built from its repository
 * with these structs as payload and user header and the type names ESTPIPE_TYPE_NAME_*
 * (iceoryx2 compares name, size and alignment), with the QoS and the sending rules of
 * docs/wire.md ("Services and QoS", "Sending a slot").
 *
 * Since wire version 3, every sensor node is its own stream (docs/wire.md, "Stream rules"): its
 * own stream_id, seq = k - 1 (estpipe_seq_of), one END/ABORT marker per node with node set
 * and seq = k = the node's last instant sent; up to ESTPIPE_SLOTS_MAX_PUBLISHERS publishers
 * (one per node) on <prefix>/slots.
 */
#ifndef ESTPIPE_WIRE_H
#define ESTPIPE_WIRE_H

#include <stddef.h>
#include <stdint.h>

#define ESTPIPE_WIRE_VERSION 6u

#define ESTPIPE_MAX_NX 8
#define ESTPIPE_MAX_NY 4
#define ESTPIPE_MAX_NODES 8
#define ESTPIPE_COV_LEN (ESTPIPE_MAX_NX * (ESTPIPE_MAX_NX + 1) / 2)

#define ESTPIPE_SLOT_DATA 0u
#define ESTPIPE_SLOT_END 1u
#define ESTPIPE_SLOT_ABORT 2u

#define ESTPIPE_FLAG_TRIGGERED (1u << 0)
#define ESTPIPE_FLAG_TOKEN_BLOCKED (1u << 1)
#define ESTPIPE_FLAG_CENSORED (1u << 2)
#define ESTPIPE_FLAG_RANDOM_LOSS (1u << 3)
#define ESTPIPE_FLAG_OCCLUDED (1u << 4)
#define ESTPIPE_FLAG_TOKENS (1u << 5)
#define ESTPIPE_FLAG_NET_LOST (1u << 30)
#define ESTPIPE_FLAG_IPC_LOST (1u << 31)

#define ESTPIPE_STATUS_OK 0u
#define ESTPIPE_STATUS_REFUSED 1u
#define ESTPIPE_STATUS_NONE_YET 2u

#define ESTPIPE_COV_NONE 0u
#define ESTPIPE_COV_ESTIMATE 1u
#define ESTPIPE_COV_BOUND 2u

#define ESTPIPE_READY_EVENT 1u
#define ESTPIPE_SLOTS_MAX_PUBLISHERS ESTPIPE_MAX_NODES
#define ESTPIPE_MAX_SUBSCRIBER_BUFFER 4096u
#define ESTPIPE_ESTIMATE_HISTORY 16u

#define ESTPIPE_TYPE_NAME_SLOT "estpipe::wire::Slot"
#define ESTPIPE_TYPE_NAME_STREAMHEADER "estpipe::wire::StreamHeader"
#define ESTPIPE_TYPE_NAME_ESTIMATE "estpipe::wire::Estimate"
#define ESTPIPE_TYPE_NAME_TRUTH "estpipe::wire::Truth"

/* One sensor node's observation of one sampling instant: the payload of <prefix>/slots. */
typedef struct estpipe_Slot {
    uint32_t version;
    uint32_t kind;
    uint64_t stream_id;
    uint64_t seq;
    uint32_t k;
    uint8_t node;
    uint8_t nodes;
    uint8_t ny;
    uint8_t delivered;
    uint32_t flags;
    uint32_t tokens;
    uint64_t send_ns;
    uint64_t period_ns;
    uint64_t stream_start_ns;
    double y[ESTPIPE_MAX_NY];
} estpipe_Slot;

/* The stream's shape: the iceoryx2 user header of every slot. */
typedef struct estpipe_StreamHeader {
    uint32_t version;
    uint8_t nodes;
    uint8_t nx;
    uint16_t reserved;
    uint8_t ny[ESTPIPE_MAX_NODES];
    uint64_t model;
    uint8_t scenario[32];
} estpipe_StreamHeader;

/* One estimator's estimate x_k, its covariance, status and timing: the payload of <prefix>/estimates. */
typedef struct estpipe_Estimate {
    uint32_t version;
    uint32_t k;
    uint64_t stream_id;
    uint64_t seq;
    uint32_t estimator;
    uint32_t nx;
    uint8_t name[16];
    uint32_t status;
    uint32_t cov_kind;
    double x[ESTPIPE_MAX_NX];
    double p[ESTPIPE_COV_LEN];
    uint64_t slot_send_ns;
    uint64_t receive_ns;
    uint64_t step_done_ns;
    uint32_t late_folded;
    uint32_t revised_from;
} estpipe_Estimate;

/* The true state (evaluation only): the payload of <prefix>/truth. */
typedef struct estpipe_Truth {
    uint32_t version;
    uint32_t k;
    uint64_t stream_id;
    uint32_t nx;
    uint32_t reserved;
    double x[ESTPIPE_MAX_NX];
} estpipe_Truth;

/* The layout of docs/wire.md, checked by the compiler. */
_Static_assert(offsetof(estpipe_Slot, version) == 0, "estpipe_Slot.version offset");
_Static_assert(offsetof(estpipe_Slot, kind) == 4, "estpipe_Slot.kind offset");
_Static_assert(offsetof(estpipe_Slot, stream_id) == 8, "estpipe_Slot.stream_id offset");
_Static_assert(offsetof(estpipe_Slot, seq) == 16, "estpipe_Slot.seq offset");
_Static_assert(offsetof(estpipe_Slot, k) == 24, "estpipe_Slot.k offset");
_Static_assert(offsetof(estpipe_Slot, node) == 28, "estpipe_Slot.node offset");
_Static_assert(offsetof(estpipe_Slot, nodes) == 29, "estpipe_Slot.nodes offset");
_Static_assert(offsetof(estpipe_Slot, ny) == 30, "estpipe_Slot.ny offset");
_Static_assert(offsetof(estpipe_Slot, delivered) == 31, "estpipe_Slot.delivered offset");
_Static_assert(offsetof(estpipe_Slot, flags) == 32, "estpipe_Slot.flags offset");
_Static_assert(offsetof(estpipe_Slot, tokens) == 36, "estpipe_Slot.tokens offset");
_Static_assert(offsetof(estpipe_Slot, send_ns) == 40, "estpipe_Slot.send_ns offset");
_Static_assert(offsetof(estpipe_Slot, period_ns) == 48, "estpipe_Slot.period_ns offset");
_Static_assert(offsetof(estpipe_Slot, stream_start_ns) == 56, "estpipe_Slot.stream_start_ns offset");
_Static_assert(offsetof(estpipe_Slot, y) == 64, "estpipe_Slot.y offset");
_Static_assert(sizeof(estpipe_Slot) == 96, "estpipe_Slot size");
_Static_assert(_Alignof(estpipe_Slot) == 8, "estpipe_Slot alignment");

_Static_assert(offsetof(estpipe_StreamHeader, version) == 0, "estpipe_StreamHeader.version offset");
_Static_assert(offsetof(estpipe_StreamHeader, nodes) == 4, "estpipe_StreamHeader.nodes offset");
_Static_assert(offsetof(estpipe_StreamHeader, nx) == 5, "estpipe_StreamHeader.nx offset");
_Static_assert(offsetof(estpipe_StreamHeader, reserved) == 6, "estpipe_StreamHeader.reserved offset");
_Static_assert(offsetof(estpipe_StreamHeader, ny) == 8, "estpipe_StreamHeader.ny offset");
_Static_assert(offsetof(estpipe_StreamHeader, model) == 16, "estpipe_StreamHeader.model offset");
_Static_assert(offsetof(estpipe_StreamHeader, scenario) == 24, "estpipe_StreamHeader.scenario offset");
_Static_assert(sizeof(estpipe_StreamHeader) == 56, "estpipe_StreamHeader size");
_Static_assert(_Alignof(estpipe_StreamHeader) == 8, "estpipe_StreamHeader alignment");

_Static_assert(offsetof(estpipe_Estimate, version) == 0, "estpipe_Estimate.version offset");
_Static_assert(offsetof(estpipe_Estimate, k) == 4, "estpipe_Estimate.k offset");
_Static_assert(offsetof(estpipe_Estimate, stream_id) == 8, "estpipe_Estimate.stream_id offset");
_Static_assert(offsetof(estpipe_Estimate, seq) == 16, "estpipe_Estimate.seq offset");
_Static_assert(offsetof(estpipe_Estimate, estimator) == 24, "estpipe_Estimate.estimator offset");
_Static_assert(offsetof(estpipe_Estimate, nx) == 28, "estpipe_Estimate.nx offset");
_Static_assert(offsetof(estpipe_Estimate, name) == 32, "estpipe_Estimate.name offset");
_Static_assert(offsetof(estpipe_Estimate, status) == 48, "estpipe_Estimate.status offset");
_Static_assert(offsetof(estpipe_Estimate, cov_kind) == 52, "estpipe_Estimate.cov_kind offset");
_Static_assert(offsetof(estpipe_Estimate, x) == 56, "estpipe_Estimate.x offset");
_Static_assert(offsetof(estpipe_Estimate, p) == 120, "estpipe_Estimate.p offset");
_Static_assert(offsetof(estpipe_Estimate, slot_send_ns) == 408, "estpipe_Estimate.slot_send_ns offset");
_Static_assert(offsetof(estpipe_Estimate, receive_ns) == 416, "estpipe_Estimate.receive_ns offset");
_Static_assert(offsetof(estpipe_Estimate, step_done_ns) == 424, "estpipe_Estimate.step_done_ns offset");
_Static_assert(offsetof(estpipe_Estimate, late_folded) == 432, "estpipe_Estimate.late_folded offset");
_Static_assert(offsetof(estpipe_Estimate, revised_from) == 436, "estpipe_Estimate.revised_from offset");
_Static_assert(sizeof(estpipe_Estimate) == 440, "estpipe_Estimate size");
_Static_assert(_Alignof(estpipe_Estimate) == 8, "estpipe_Estimate alignment");

_Static_assert(offsetof(estpipe_Truth, version) == 0, "estpipe_Truth.version offset");
_Static_assert(offsetof(estpipe_Truth, k) == 4, "estpipe_Truth.k offset");
_Static_assert(offsetof(estpipe_Truth, stream_id) == 8, "estpipe_Truth.stream_id offset");
_Static_assert(offsetof(estpipe_Truth, nx) == 16, "estpipe_Truth.nx offset");
_Static_assert(offsetof(estpipe_Truth, reserved) == 20, "estpipe_Truth.reserved offset");
_Static_assert(offsetof(estpipe_Truth, x) == 24, "estpipe_Truth.x offset");
_Static_assert(sizeof(estpipe_Truth) == 88, "estpipe_Truth size");
_Static_assert(_Alignof(estpipe_Truth) == 8, "estpipe_Truth alignment");

/* Index of P[i][j] (i <= j) in estpipe_Estimate.p: the upper triangle row by row. */
static inline size_t estpipe_packed_index(size_t nx, size_t i, size_t j) {
    if (i > j) {
        size_t t = i;
        i = j;
        j = t;
    }
    return i * nx - (i * (i - 1)) / 2 + (j - i); /* i = 0: 0 · (i − 1) wraps to 0 */
}

/* A node's sequence number of its slot of instant k (k >= 1): k - 1. */
static inline uint64_t estpipe_seq_of(uint32_t k) {
    return k == 0 ? 0 : (uint64_t)k - 1;
}

#endif /* ESTPIPE_WIRE_H */
