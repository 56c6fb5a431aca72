/*
 * Counts the guest instructions QEMU executes, exactly and deterministically, and writes the
 * total to a file when the emulation ends:
 *
 *   qemu-system-arm ... -plugin ./libinsn_count.so,out=count.txt
 *
 * With a step marker it also writes one line per marked interval:
 *
 *   ... -plugin ./libinsn_count.so,out=count.txt,mark=ADDR:SIZE,marks=ADDR:768,steps=steps.txt
 *
 * `mark=ADDR:SIZE` is the firmware's marker function (`run::mark::step_mark`, address and size
 * from the ELF's symbol table; the Thumb bit of ADDR is ignored), which the driver calls with
 * an instant k and a code: once before its loop (k = 0), and just before (code BEGIN = 128)
 * and just after every step (the step's branch code). `marks=ADDR:768` is the marker's table
 * (`MARKS`): the marker reads one byte at `MARKS[k & 0xff]`, one at `MARKS[256 + (k >> 8)]`
 * and one at `MARKS[512 + code]`, so the addresses of its three loads carry k and the code
 * (this QEMU's plugin API, version 1, shows the address of a guest memory access but neither
 * registers nor loaded values). Each line of `steps=FILE` is
 *
 *   k code instructions
 *
 * where `instructions` counts everything executed from the previous marker call to this one:
 * for a line with code 128 the driver's bookkeeping before step k, for the other codes step k
 * itself. The interval that ends at the k = 0 call (start-up) is not written. The marker's
 * own instructions are counted in neither the lines nor the total `insns` (they are reported
 * as `mark_insns`); the caller's argument set-up and call instruction are. A marker call that
 * does not read each of the three regions once is counted in `mark_errors`.
 *
 * With `pcs=FILE` it also counts executions per instruction address (below 1 MiB, the
 * board's code flash) and writes one line `ADDR COUNT` per executed address: a per-function
 * profile once the addresses are mapped to the ELF's symbols (`.ci/firmware-profile`).
 *
 * Built against QEMU's stable plugin C API (plugin API version 1, QEMU 7.x). Debian's QEMU has
 * plugin support built in but ships neither plugins nor qemu-plugin.h, so the handful of
 * declarations used here are written out below from the API's documentation; the functions
 * themselves are resolved from the qemu-system-arm binary at load time.
 *
 * Each translated instruction gets an inline "add 1 to a 64-bit counter" op, executed before
 * the instruction, so the count is exact even when a translation block is left early (the
 * semihosting BKPT that ends the run). One vCPU only (the mps2 boards have one).
 */
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef uint64_t qemu_plugin_id_t;
struct qemu_plugin_tb;
struct qemu_plugin_insn;

typedef struct {
    const char *target_name;
    struct {
        int min;
        int cur;
    } version;
    bool system_emulation;
    union {
        struct {
            int smp_vcpus;
            int max_vcpus;
        } system;
    };
} qemu_info_t;

enum qemu_plugin_op { QEMU_PLUGIN_INLINE_ADD_U64 };
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS, QEMU_PLUGIN_CB_R_REGS, QEMU_PLUGIN_CB_RW_REGS };
enum qemu_plugin_mem_rw { QEMU_PLUGIN_MEM_R = 1, QEMU_PLUGIN_MEM_W, QEMU_PLUGIN_MEM_RW };
typedef uint32_t qemu_plugin_meminfo_t;

typedef void (*qemu_plugin_vcpu_tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);
typedef void (*qemu_plugin_udata_cb_t)(qemu_plugin_id_t id, void *userdata);
typedef void (*qemu_plugin_vcpu_udata_cb_t)(unsigned int vcpu_index, void *userdata);
typedef void (*qemu_plugin_vcpu_mem_cb_t)(unsigned int vcpu_index, qemu_plugin_meminfo_t info,
                                          uint64_t vaddr, void *userdata);

extern void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id,
                                                  qemu_plugin_vcpu_tb_trans_cb_t cb);
extern size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
extern struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb,
                                                        size_t idx);
extern uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
extern void qemu_plugin_register_vcpu_insn_exec_inline(struct qemu_plugin_insn *insn,
                                                       enum qemu_plugin_op op, void *ptr,
                                                       uint64_t imm);
extern void qemu_plugin_register_vcpu_insn_exec_cb(struct qemu_plugin_insn *insn,
                                                   qemu_plugin_vcpu_udata_cb_t cb,
                                                   enum qemu_plugin_cb_flags flags,
                                                   void *userdata);
extern void qemu_plugin_register_vcpu_mem_cb(struct qemu_plugin_insn *insn,
                                             qemu_plugin_vcpu_mem_cb_t cb,
                                             enum qemu_plugin_cb_flags flags,
                                             enum qemu_plugin_mem_rw rw, void *userdata);
extern void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb,
                                           void *userdata);

#define EXPORT __attribute__((visibility("default")))

EXPORT int qemu_plugin_version = 1;

/* Instructions outside the marker, and inside it. */
static uint64_t executed;
static uint64_t in_mark;
static char out_path[4096];

/* The marker function [mark_lo, mark_hi) and its table [marks_lo, marks_lo + MARKS_LEN). */
#define MARKS_LEN 768
static uint64_t mark_lo, mark_hi, marks_lo;
static bool marking;
static FILE *steps_out;

/* The marker call being decoded: its k and branch (filled by its loads), the instructions of
 * the step it closes, and whether there is one (false before the first call). */
static struct {
    bool open;
    uint32_t k;
    uint32_t branch;
    unsigned seen; /* bit i: region i (k low, k high, branch) was read */
    uint64_t insns;
} cur;
static uint64_t last_mark;
static uint64_t marks_seen;
static uint64_t mark_errors;

static void flush_step(void)
{
    if (!cur.open) {
        return;
    }
    if (cur.seen != 7) {
        mark_errors++;
    }
    /* The call with k = 0 marks the start of the loop: what precedes it is not a step. */
    if (cur.k != 0 && steps_out) {
        fprintf(steps_out, "%u %u %llu\n", cur.k, cur.branch, (unsigned long long)cur.insns);
    }
    cur.open = false;
}

static void on_mark_entry(unsigned int vcpu, void *userdata)
{
    (void)vcpu;
    (void)userdata;
    flush_step();
    cur.open = true;
    cur.k = 0;
    cur.branch = 0;
    cur.seen = 0;
    cur.insns = executed - last_mark;
    last_mark = executed;
    marks_seen++;
}

static void on_mark_load(unsigned int vcpu, qemu_plugin_meminfo_t info, uint64_t vaddr,
                         void *userdata)
{
    (void)vcpu;
    (void)info;
    (void)userdata;
    if (!cur.open || vaddr < marks_lo || vaddr >= marks_lo + MARKS_LEN) {
        return;
    }
    uint64_t off = vaddr - marks_lo;
    unsigned region = (unsigned)(off / 256), byte = (unsigned)(off % 256);
    if (cur.seen & (1u << region)) {
        mark_errors++;
    }
    cur.seen |= 1u << region;
    if (region == 0) {
        cur.k |= byte;
    } else if (region == 1) {
        cur.k |= byte << 8;
    } else {
        cur.branch = byte;
    }
}

/* Per-address counts (pcs=): one counter per halfword below PCS_LIMIT. */
#define PCS_LIMIT (1u << 20)
static uint64_t *pc_counts;
static char pcs_path[4096];

static void on_translate(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t pc = qemu_plugin_insn_vaddr(insn);
        if (pc_counts && pc < PCS_LIMIT) {
            qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64,
                                                       &pc_counts[pc >> 1], 1);
        }
        if (marking && pc >= mark_lo && pc < mark_hi) {
            qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64,
                                                       &in_mark, 1);
            if (pc == mark_lo) {
                qemu_plugin_register_vcpu_insn_exec_cb(insn, on_mark_entry,
                                                       QEMU_PLUGIN_CB_NO_REGS, NULL);
            }
            /* Every access (QEMU 7.2 with QEMU_PLUGIN_MEM_R alone reported some stores and
             * missed the table's loads); the callback keeps those inside the table. */
            qemu_plugin_register_vcpu_mem_cb(insn, on_mark_load, QEMU_PLUGIN_CB_NO_REGS,
                                             QEMU_PLUGIN_MEM_RW, NULL);
        } else {
            qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64,
                                                       &executed, 1);
        }
    }
}

static void write_count(qemu_plugin_id_t id, void *userdata)
{
    (void)id;
    (void)userdata;
    flush_step();
    if (steps_out) {
        fclose(steps_out);
        steps_out = NULL;
    }
    FILE *f = out_path[0] ? fopen(out_path, "w") : stderr;
    if (!f) {
        return;
    }
    fprintf(f, "insns %llu\n", (unsigned long long)executed);
    if (marking) {
        fprintf(f, "mark_calls %llu\n", (unsigned long long)marks_seen);
        fprintf(f, "mark_insns %llu\n", (unsigned long long)in_mark);
        /* Marker calls that did not read each region once: the decoding went wrong. */
        fprintf(f, "mark_errors %llu\n", (unsigned long long)mark_errors);
    }
    if (f != stderr) {
        fclose(f);
    }
    FILE *p = pc_counts ? fopen(pcs_path, "w") : NULL;
    if (p) {
        for (uint64_t i = 0; i < PCS_LIMIT / 2; i++) {
            if (pc_counts[i]) {
                fprintf(p, "%llx %llu\n", (unsigned long long)(i << 1),
                        (unsigned long long)pc_counts[i]);
            }
        }
        fclose(p);
    }
}

/* "ADDR:SIZE" (each decimal or 0x-hex) into [lo, hi); bit 0 of ADDR (a Thumb function
 * symbol's) is dropped. */
static bool parse_range(const char *s, uint64_t *lo, uint64_t *hi)
{
    char *end;
    *lo = strtoull(s, &end, 0) & ~(uint64_t)1;
    if (*end != ':') {
        return false;
    }
    uint64_t size = strtoull(end + 1, &end, 0);
    if (*end != '\0' || size == 0) {
        return false;
    }
    *hi = *lo + size;
    return true;
}

EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc,
                               char **argv)
{
    (void)info;
    const char *steps_path = NULL;
    bool have_mark = false, have_marks = false;
    for (int i = 0; i < argc; i++) {
        uint64_t hi;
        if (strncmp(argv[i], "out=", 4) == 0) {
            snprintf(out_path, sizeof out_path, "%s", argv[i] + 4);
        } else if (strncmp(argv[i], "mark=", 5) == 0 &&
                   parse_range(argv[i] + 5, &mark_lo, &mark_hi)) {
            have_mark = true;
        } else if (strncmp(argv[i], "marks=", 6) == 0 &&
                   parse_range(argv[i] + 6, &marks_lo, &hi) && hi - marks_lo == MARKS_LEN) {
            have_marks = true;
        } else if (strncmp(argv[i], "steps=", 6) == 0) {
            steps_path = argv[i] + 6;
        } else if (strncmp(argv[i], "pcs=", 4) == 0) {
            snprintf(pcs_path, sizeof pcs_path, "%s", argv[i] + 4);
            pc_counts = calloc(PCS_LIMIT / 2, sizeof *pc_counts);
            if (!pc_counts) {
                return -1;
            }
        } else {
            fprintf(stderr, "insn_count: bad argument %s\n", argv[i]);
            return -1;
        }
    }
    if (have_mark != have_marks || (steps_path && !have_mark)) {
        fprintf(stderr, "insn_count: mark=, marks= and steps= go together\n");
        return -1;
    }
    marking = have_mark;
    if (steps_path) {
        steps_out = fopen(steps_path, "w");
        if (!steps_out) {
            fprintf(stderr, "insn_count: cannot write %s\n", steps_path);
            return -1;
        }
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
    qemu_plugin_register_atexit_cb(id, write_count, NULL);
    return 0;
}
