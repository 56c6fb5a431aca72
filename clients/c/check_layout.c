/* Checks every size, alignment and offset of estpipe_wire.h at run time (the header checks
 * them at compile time) and prints the layout, one line per type and field:
 *
 *     Slot size 96 align 8
 *     Slot.version offset 0 size 4
 *
 * wire/tests/layout.rs compiles and runs it with the system `cc` and compares the output
 * with the Rust types. Exit code 1 names the first mismatch.
 */
#include <stdio.h>

#include "estpipe_wire.h"

struct expected {
    const char *type;
    const char *field; /* NULL: the type itself */
    size_t offset_or_size, size_or_align;
    size_t actual_a, actual_b;
};

#define TYPE(t, size, align) {#t, NULL, size, align, sizeof(estpipe_##t), _Alignof(estpipe_##t)}
#define FIELD(t, f, off, size) \
    {#t, #f, off, size, offsetof(estpipe_##t, f), sizeof(((estpipe_##t *)0)->f)}

static const struct expected layout[] = {
    TYPE(Slot, 96, 8),
    FIELD(Slot, version, 0, 4),
    FIELD(Slot, kind, 4, 4),
    FIELD(Slot, stream_id, 8, 8),
    FIELD(Slot, seq, 16, 8),
    FIELD(Slot, k, 24, 4),
    FIELD(Slot, node, 28, 1),
    FIELD(Slot, nodes, 29, 1),
    FIELD(Slot, ny, 30, 1),
    FIELD(Slot, delivered, 31, 1),
    FIELD(Slot, flags, 32, 4),
    FIELD(Slot, tokens, 36, 4),
    FIELD(Slot, send_ns, 40, 8),
    FIELD(Slot, period_ns, 48, 8),
    FIELD(Slot, stream_start_ns, 56, 8),
    FIELD(Slot, y, 64, 32),
    TYPE(StreamHeader, 56, 8),
    FIELD(StreamHeader, version, 0, 4),
    FIELD(StreamHeader, nodes, 4, 1),
    FIELD(StreamHeader, nx, 5, 1),
    FIELD(StreamHeader, reserved, 6, 2),
    FIELD(StreamHeader, ny, 8, 8),
    FIELD(StreamHeader, model, 16, 8),
    FIELD(StreamHeader, scenario, 24, 32),
    TYPE(Estimate, 440, 8),
    FIELD(Estimate, version, 0, 4),
    FIELD(Estimate, k, 4, 4),
    FIELD(Estimate, stream_id, 8, 8),
    FIELD(Estimate, seq, 16, 8),
    FIELD(Estimate, estimator, 24, 4),
    FIELD(Estimate, nx, 28, 4),
    FIELD(Estimate, name, 32, 16),
    FIELD(Estimate, status, 48, 4),
    FIELD(Estimate, cov_kind, 52, 4),
    FIELD(Estimate, x, 56, 64),
    FIELD(Estimate, p, 120, 288),
    FIELD(Estimate, slot_send_ns, 408, 8),
    FIELD(Estimate, receive_ns, 416, 8),
    FIELD(Estimate, step_done_ns, 424, 8),
    FIELD(Estimate, late_folded, 432, 4),
    FIELD(Estimate, revised_from, 436, 4),
    TYPE(Truth, 88, 8),
    FIELD(Truth, version, 0, 4),
    FIELD(Truth, k, 4, 4),
    FIELD(Truth, stream_id, 8, 8),
    FIELD(Truth, nx, 16, 4),
    FIELD(Truth, reserved, 20, 4),
    FIELD(Truth, x, 24, 64),
};

int main(void) {
    int failed = 0;
    for (size_t i = 0; i < sizeof layout / sizeof layout[0]; i++) {
        const struct expected *e = &layout[i];
        if (e->actual_a != e->offset_or_size || e->actual_b != e->size_or_align) {
            fprintf(stderr, "%s%s%s: expected %zu/%zu, got %zu/%zu\n", e->type,
                    e->field ? "." : "", e->field ? e->field : "", e->offset_or_size,
                    e->size_or_align, e->actual_a, e->actual_b);
            failed = 1;
        }
        if (e->field) {
            printf("%s.%s offset %zu size %zu\n", e->type, e->field, e->actual_a, e->actual_b);
        } else {
            printf("%s size %zu align %zu\n", e->type, e->actual_a, e->actual_b);
        }
    }
    if (estpipe_seq_of(1) != 0 || estpipe_seq_of(300) != 299 || estpipe_seq_of(0) != 0) {
        fprintf(stderr, "estpipe_seq_of is wrong\n");
        failed = 1;
    }
    if (estpipe_packed_index(3, 2, 1) != 4 || estpipe_packed_index(8, 7, 7) != ESTPIPE_COV_LEN - 1) {
        fprintf(stderr, "estpipe_packed_index is wrong\n");
        failed = 1;
    }
    return failed;
}
