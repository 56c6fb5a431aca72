/* The estimation pipeline's C client library (crate clients/c/ffi, `estpipe-c`): publish sensor
 * slots to `ipc-runner run` and receive its estimates over iceoryx2 shared memory.
 *
 * Why not iceoryx2's own C binding: iceoryx2 0.10's C binding is built with cmake from the
 * iceoryx2 repository and is not on crates.io (`iceoryx2-ffi` there stops at 0.4.1,
 * `iceoryx2-ffi-c` is not published). This library is built by cargo with the product and
 * carries the product's own code: the services opened with the contract's QoS, a slot sent
 * until every subscriber has it, the wait for a subscriber and the linger (docs/wire.md).
 *
 *     cargo build --release -p estpipe-c          # target/release/libestpipe_c.a
 *     make -C clients/c                           # the two examples, statically linked
 *
 * Every function returns a status code: ESTPIPE_OK (0), a positive outcome (timeout, gave up,
 * stopped) or a negative error, with a one-line message from estpipe_last_error(). A null
 * pointer, a misaligned one or a string that is not UTF-8 gives ESTPIPE_ERR_NULL or
 * ESTPIPE_ERR_ARG; nothing panics across the boundary (ESTPIPE_ERR_PANIC at worst). Pointers
 * that are not null must point to what the function says (a closed handle must not be used
 * again: the library cannot tell). A handle is used by one thread at a time.
 *
 * Signals: opening a publisher or subscriber installs the product's handlers (docs/security.md,
 * "Signals"): SIGINT, SIGTERM and SIGHUP set a flag instead of ending the process, a blocked
 * send or wait returns ESTPIPE_STOPPED, and estpipe_stop_requested() tells your loop to end
 * (send the ABORT markers, close).
 */
#ifndef ESTPIPE_H
#define ESTPIPE_H

#include <stdint.h>

#include "estpipe_wire.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Status codes. */
#define ESTPIPE_OK 0
#define ESTPIPE_TIMEOUT 1       /* no subscriber (publisher_open) / no estimate (receive) in time */
#define ESTPIPE_GAVE_UP 2       /* a slot did not reach every subscriber: one died, or the timeout ran out */
#define ESTPIPE_STOPPED 3       /* SIGINT/SIGTERM/SIGHUP: the data slot was not sent, the wait ended */
#define ESTPIPE_ERR_NULL (-1)   /* a null pointer where one is required */
#define ESTPIPE_ERR_ARG (-2)    /* misaligned pointer, not UTF-8, a header or slot outside the contract */
#define ESTPIPE_ERR_IPC (-3)    /* iceoryx2 failed (node, port, send, receive) */
#define ESTPIPE_ERR_PANIC (-4)  /* an internal error, caught at the boundary */
#define ESTPIPE_ERR_CONTRACT (-5) /* a peer outside the contract (service QoS, wire version) */

typedef struct EstpipePublisher estpipe_publisher;
typedef struct EstpipeSubscriber estpipe_subscriber;

/* The message of the last failure on this thread ("" after a success); valid until the next
 * estpipe_* call on this thread. */
const char *estpipe_last_error(void);

/* CLOCK_MONOTONIC in ns, the clock of send_ns and stream_start_ns. */
uint64_t estpipe_monotonic_ns(void);

/* 1 once SIGINT/SIGTERM/SIGHUP arrived, else 0. */
int estpipe_stop_requested(void);

/* Parses the JSON line of `ipc-runner stream-header` (wire_version, scenario, nodes, nx, ny,
 * model as a 0x hex string) into *out, checked as the runner checks a header. */
int estpipe_header_from_json(const char *json, estpipe_StreamHeader *out);

/* Opens <prefix>/slots and <prefix>/slots-ready with the contract's QoS, creates a publisher
 * whose every slot carries *header, and waits up to timeout_ms (0: for ever) for a subscriber.
 * ESTPIPE_OK with *out set; ESTPIPE_TIMEOUT, ESTPIPE_STOPPED or an error with *out = NULL. */
int estpipe_publisher_open(const char *prefix, const estpipe_StreamHeader *header,
                           uint32_t timeout_ms, estpipe_publisher **out);

/* Sends *slot until every subscriber has it (a full queue blocks; a subscriber not yet
 * connected gets it again; one that does not read for 2 s is no longer waited for). The slot
 * is first checked against the header (version, node, seq = k - 1, ny, finite y, y 0 past ny, ...):
 * ESTPIPE_ERR_ARG names the fault and nothing is sent. timeout_ms bounds the send (0: none for
 * a data slot, 5 s for an END/ABORT marker, which is sent even after a stop signal and gets
 * its send_ns here). ESTPIPE_OK, ESTPIPE_GAVE_UP, ESTPIPE_STOPPED or an error. */
int estpipe_publish(estpipe_publisher *publisher, const estpipe_Slot *slot, uint32_t timeout_ms);

/* Notifies <prefix>/slots-ready: call it after each instant's slots. */
int estpipe_instant_done(estpipe_publisher *publisher);

/* The subscribers of <prefix>/slots now (>= 0), or an error. */
int estpipe_publisher_subscribers(estpipe_publisher *publisher);

/* Waits up to linger_ms for the subscribers to detach (the runner reads the last slots from
 * this publisher's memory), then closes and frees the publisher. NULL does nothing. */
int estpipe_publisher_close(estpipe_publisher *publisher, uint32_t linger_ms);

/* Opens <prefix>/estimates with the contract's QoS and subscribes (a subscriber that connects
 * while the runner runs first gets the newest estimates, the service's history). */
int estpipe_subscriber_open(const char *prefix, estpipe_subscriber **out);

/* Copies the next estimate into *out, waiting up to timeout_ms (0: only looks). ESTPIPE_OK,
 * ESTPIPE_TIMEOUT, ESTPIPE_STOPPED, ESTPIPE_ERR_CONTRACT (another wire version; *out holds
 * it) or an error. */
int estpipe_receive(estpipe_subscriber *subscriber, estpipe_Estimate *out, uint32_t timeout_ms);

/* Closes and frees the subscriber. NULL does nothing. */
int estpipe_subscriber_close(estpipe_subscriber *subscriber);

#ifdef __cplusplus
}
#endif

#endif /* ESTPIPE_H */
