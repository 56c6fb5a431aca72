/* Sensor publisher example in C: publishes the slots of a slot log (docs/replay.md) to
 * ipc-runner, as clients/python/examples/publish_slots.py does.
 *
 *     ipc-runner stream-header --scenario linear > out/header.json
 *     clients/c/build/publish_slots --prefix mine --header out/header.json --slots slots.csv
 *
 * The header is the JSON line of `ipc-runner stream-header`, parsed and checked by the library
 * (estpipe_header_from_json: the model fingerprint is a 64-bit hex string and the checks are
 * the runner's, so C does not repeat them). The log is read by the rules that decide what is
 * sent (those of `ipc-runner replay`): a delivered row goes out with its measurement, a row
 * with delivered = 0 as a channel dropout, and a row flagged lost (FLAG_IPC_LOST or
 * FLAG_NET_LOST, undelivered), a late row (late_after > 0), a node missing from an instant and
 * a missing instant are *not sent*: the gap in the node's seq is the runner's lost slot
 * (docs/wire.md, Stream rules). A malformed row is refused with its line before anything is
 * sent (exit 2); replay's remaining refusals (line and file limits) are replay's.
 *
 * The slots of an instant go out in node order, then one notification on <prefix>/slots-ready;
 * each node's END marker (k = the log's last instant) closes its stream, ABORT after SIGINT.
 * Exit codes: 0 done, 1 a failure, 2 bad input, 3 no runner within --connect-timeout.
 */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "estpipe.h"

#define ME "publish_slots"

/* One row of the log: what was read for (k, node). */
enum state { ABSENT = 0, DELIVERED, DROPPED, LOST };

struct row {
    uint32_t k;
    uint8_t node;
    uint8_t state;
    uint8_t has_tokens;
    uint32_t flags;
    uint32_t tokens;
    double y[ESTPIPE_MAX_NY];
};

static void usage(void) {
    fprintf(stderr,
            "usage: " ME " --header FILE --slots CSV [--prefix P] [--rate HZ] "
            "[--connect-timeout S]\n");
}

static char *read_file(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, ME ": error: %s: %s\n", path, strerror(errno));
        return NULL;
    }
    size_t cap = 4096, len = 0;
    char *buf = malloc(cap);
    size_t n;
    while (buf && (n = fread(buf + len, 1, cap - len - 1, f)) > 0) {
        len += n;
        if (cap - len - 1 == 0) {
            char *b = realloc(buf, cap * 2);
            if (!b) {
                free(buf);
                buf = NULL;
                break;
            }
            buf = b;
            cap *= 2;
        }
    }
    fclose(f);
    if (buf) buf[len] = 0;
    return buf;
}

/* Trims spaces and a trailing CR in place. */
static char *trim(char *s) {
    while (*s == ' ' || *s == '\t') s++;
    size_t n = strlen(s);
    while (n > 0 && (s[n - 1] == ' ' || s[n - 1] == '\t' || s[n - 1] == '\r' || s[n - 1] == '\n'))
        s[--n] = 0;
    return s;
}

/* Splits a line at commas into at most max trimmed cells; returns their number. */
static int split(char *line, char **cells, int max) {
    int n = 0;
    char *s = line;
    while (n < max) {
        char *c = strchr(s, ',');
        if (c) *c = 0;
        cells[n++] = trim(s);
        if (!c) break;
        s = c + 1;
    }
    return n;
}

/* A decimal unsigned integer (an optional '+', digits only) of at most max. */
static int parse_uint(const char *s, uint64_t max, uint64_t *out) {
    if (*s == '+') s++;
    if (!*s) return -1;
    uint64_t v = 0;
    for (; *s; s++) {
        if (*s < '0' || *s > '9') return -1;
        unsigned d = (unsigned)(*s - '0');
        if (v > (max - d) / 10) return -1;
        v = v * 10 + d;
    }
    *out = v;
    return 0;
}

/* A float as Rust's f64::from_str reads it: decimal or inf/nan, the whole cell, no hex. */
static int parse_float(const char *s, double *out) {
    if (!*s || strchr(s, 'x') || strchr(s, 'X') || strchr(s, '_')) return -1;
    char *end;
    errno = 0;
    *out = strtod(s, &end);
    return *end ? -1 : 0;
}

static int find_col(char **cells, int n, const char *name) {
    for (int i = 0; i < n; i++)
        if (strcmp(cells[i], name) == 0) return i;
    return -1;
}

#define MAX_COLS 256

/* Reads the log into *rows (increasing k); 0, or -1 after printing the file, line and field. */
static int read_log(const char *path, const estpipe_StreamHeader *h, struct row **rows,
                    size_t *count, size_t *late) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, ME ": error: %s: %s\n", path, strerror(errno));
        return -1;
    }
    char *line = NULL;
    size_t cap = 0;
    ssize_t len;
    char *cells[MAX_COLS];
    int ck, cn, cd, cf, ct, cl, cy[ESTPIPE_MAX_NY], ny_max = 0;
    for (int m = 0; m < h->nodes; m++)
        if (h->ny[m] > ny_max) ny_max = h->ny[m];
    if ((len = getline(&line, &cap, f)) < 0) {
        fprintf(stderr, ME ": error: %s: empty slot log (no header line)\n", path);
        goto fail;
    }
    int ncols = split(line, cells, MAX_COLS);
    ck = find_col(cells, ncols, "k");
    cn = find_col(cells, ncols, "node");
    cd = find_col(cells, ncols, "delivered");
    cf = find_col(cells, ncols, "flags");
    ct = find_col(cells, ncols, "tokens");
    cl = find_col(cells, ncols, "late_after");
    if (ck < 0 || cn < 0 || cd < 0) {
        fprintf(stderr, ME ": error: %s line 1: header lacks column k, node or delivered\n", path);
        goto fail;
    }
    for (int j = 0; j < ny_max; j++) {
        char name[16];
        snprintf(name, sizeof name, "y_%d", j);
        if ((cy[j] = find_col(cells, ncols, name)) < 0) {
            fprintf(stderr, ME ": error: %s line 1: header lacks column '%s'\n", path, name);
            goto fail;
        }
    }
    size_t n = 0, rcap = 1024, ln = 1, first_of_k = 0;
    struct row *r = malloc(rcap * sizeof *r);
    if (!r) goto fail;
    *late = 0;
    while ((len = getline(&line, &cap, f)) >= 0) {
        ln++;
        if (!*trim(line)) continue;
        int nc = split(line, cells, MAX_COLS);
#define CELL(c) ((c) >= 0 && (c) < nc ? cells[c] : "")
#define BAD(field, ...)                                                      \
    do {                                                                     \
        fprintf(stderr, ME ": error: %s line %zu: %s: ", path, ln, field);   \
        fprintf(stderr, __VA_ARGS__);                                        \
        fputc('\n', stderr);                                                 \
        free(r);                                                             \
        goto fail;                                                           \
    } while (0)
        uint64_t k, node, flags = 0, tokens = 0, late_after = 0;
        if (parse_uint(CELL(ck), UINT32_MAX, &k)) BAD("k", "'%s' is not an instant", CELL(ck));
        if (k == 0) BAD("k", "k must be >= 1 (k = 0 is the prior)");
        if (parse_uint(CELL(cn), UINT64_MAX, &node)) BAD("node", "'%s' is not a node", CELL(cn));
        if (node >= h->nodes) BAD("node", "node %" PRIu64 " but the scenario has %u node(s)", node, h->nodes);
        const char *d = CELL(cd);
        int delivered;
        if (!strcmp(d, "1") || !strcmp(d, "true")) delivered = 1;
        else if (!strcmp(d, "0") || !strcmp(d, "false")) delivered = 0;
        else BAD("delivered", "must be 0 or 1, got '%s'", d);
        if (*CELL(cf) && parse_uint(CELL(cf), UINT32_MAX, &flags)) BAD("flags", "'%s'", CELL(cf));
        int has_tokens = delivered && *CELL(ct);
        if (has_tokens && parse_uint(CELL(ct), UINT32_MAX, &tokens)) BAD("tokens", "'%s'", CELL(ct));
        if (*CELL(cl) && parse_uint(CELL(cl), UINT32_MAX, &late_after)) BAD("late_after", "'%s'", CELL(cl));
        if (late_after != 0 && late_after < k) BAD("late_after", "%" PRIu64 " is before k = %" PRIu64, late_after, k);
        uint32_t last = n ? r[n - 1].k : 0;
        if (k < last) BAD("k", "k = %" PRIu64 " after k = %u; rows must be in increasing k", k, last);
        if (k > last) first_of_k = n;
        for (size_t i = first_of_k; i < n; i++)
            if (r[i].node == node) BAD("node", "(k = %" PRIu64 ", node %" PRIu64 ") again", k, node);
        struct row row = {.k = (uint32_t)k, .node = (uint8_t)node, .flags = (uint32_t)flags};
        if (delivered) {
            row.state = DELIVERED;
            for (int j = 0; j < ny_max; j++) {
                double v;
                char field[16];
                snprintf(field, sizeof field, "y_%d", j);
                if (parse_float(CELL(cy[j]), &v)) BAD(field, "'%s' is not a number", CELL(cy[j]));
                if (j < h->ny[node]) row.y[j] = v;
            }
            row.has_tokens = (uint8_t)has_tokens;
            row.tokens = (uint32_t)tokens;
        } else {
            row.state = (flags & (ESTPIPE_FLAG_IPC_LOST | ESTPIPE_FLAG_NET_LOST)) ? LOST : DROPPED;
        }
        if (late_after) {
            /* Lost at its instant, as replay steps it before its fold (`replay --lag L`). */
            row.state = LOST;
            (*late)++;
        }
        if (n == rcap) {
            struct row *b = realloc(r, 2 * rcap * sizeof *r);
            if (!b) BAD("k", "out of memory");
            r = b;
            rcap *= 2;
        }
        r[n++] = row;
#undef BAD
#undef CELL
    }
    free(line);
    fclose(f);
    *rows = r;
    *count = n;
    return 0;
fail:
    free(line);
    fclose(f);
    return -1;
}

static void sleep_until(uint64_t due_ns) {
    for (;;) {
        uint64_t now = estpipe_monotonic_ns();
        if (now >= due_ns || estpipe_stop_requested()) return;
        uint64_t d = due_ns - now;
        if (d > 50000000) d = 50000000; /* look at the stop flag every 50 ms */
        struct timespec ts = {(time_t)(d / 1000000000u), (long)(d % 1000000000u)};
        nanosleep(&ts, NULL);
    }
}

int main(int argc, char **argv) {
    const char *prefix = "estpipe", *header_path = NULL, *slots_path = NULL;
    double rate = 0.0, connect_timeout = 30.0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        char *end = NULL;
        if (!v) {
            usage();
            return 2;
        }
        if (!strcmp(a, "--prefix")) prefix = v;
        else if (!strcmp(a, "--header")) header_path = v;
        else if (!strcmp(a, "--slots")) slots_path = v;
        else if (!strcmp(a, "--rate")) {
            rate = strtod(v, &end);
            if (*end || !(rate >= 0 && rate <= 1e6)) {
                fprintf(stderr, ME ": error: --rate %s is not in [0, 1e6]\n", v);
                return 2;
            }
        } else if (!strcmp(a, "--connect-timeout")) {
            connect_timeout = strtod(v, &end);
            if (*end || !(connect_timeout >= 0 && connect_timeout < 4e6)) {
                fprintf(stderr, ME ": error: --connect-timeout %s is not seconds >= 0\n", v);
                return 2;
            }
        } else {
            usage();
            return 2;
        }
        i++;
    }
    if (!header_path || !slots_path) {
        usage();
        return 2;
    }

    estpipe_StreamHeader header;
    char *json = read_file(header_path);
    if (!json) return 2;
    if (estpipe_header_from_json(json, &header) != ESTPIPE_OK) {
        fprintf(stderr, ME ": error: %s: %s\n", header_path, estpipe_last_error());
        free(json);
        return 2;
    }
    free(json);
    struct row *rows;
    size_t nrows, late;
    if (read_log(slots_path, &header, &rows, &nrows, &late)) return 2;
    if (late)
        fprintf(stderr,
                ME ": %zu late slot(s) in the log are published as lost (their lateness cannot "
                   "be replayed over the wire; `ipc-runner replay --lag L` folds them in)\n",
                late);

    estpipe_publisher *pub;
    fprintf(stderr, ME ": waiting for a runner on %s/slots\n", prefix);
    int rc = estpipe_publisher_open(prefix, &header, (uint32_t)(connect_timeout * 1000.0), &pub);
    if (rc != ESTPIPE_OK) {
        fprintf(stderr, ME ": error: %s\n", estpipe_last_error());
        free(rows);
        return rc == ESTPIPE_TIMEOUT ? 3 : rc == ESTPIPE_STOPPED ? 130 : 1;
    }

    uint64_t stream_id = ((uint64_t)getpid() << 32) ^ estpipe_monotonic_ns();
    uint64_t period_ns = rate > 0 ? (uint64_t)(1e9 / rate + 0.5) : 0;
    uint64_t t0 = estpipe_monotonic_ns();
    uint32_t last_k = nrows ? rows[nrows - 1].k : 0;
    size_t at = 0, sent = 0, lost = 0;
    uint32_t kind = ESTPIPE_SLOT_END;
    /* Per node, the last instant of its stream: its END/ABORT marker's k and seq. A lost slot
     * is not sent but still counts: the marker's k covers it. */
    uint32_t last_sent[ESTPIPE_MAX_NODES] = {0};
    int status = 0;
    for (uint32_t k = 1; k <= last_k; k++) {
        if (period_ns) sleep_until(t0 + (uint64_t)(k - 1) * period_ns);
        if (estpipe_stop_requested()) {
            kind = ESTPIPE_SLOT_ABORT;
            break;
        }
        /* This instant's rows, by node; a node without one is lost (not sent). */
        const struct row *of[ESTPIPE_MAX_NODES] = {0};
        for (; at < nrows && rows[at].k == k; at++) of[rows[at].node] = &rows[at];
        for (uint8_t m = 0; m < header.nodes; m++) {
            const struct row *r = of[m];
            if (!r || r->state == LOST) {
                last_sent[m] = k;
                lost++;
                continue;
            }
            int delivered = r->state == DELIVERED;
            estpipe_Slot slot = {
                .version = ESTPIPE_WIRE_VERSION,
                .kind = ESTPIPE_SLOT_DATA,
                .stream_id = stream_id,
                .seq = estpipe_seq_of(k),
                .k = k,
                .node = m,
                .nodes = header.nodes,
                .ny = header.ny[m],
                .delivered = (uint8_t)delivered,
                /* Never on the wire (docs/wire.md, Constants): the lost flags and the
                 * tokens flag, which a delivered row with a level sets again. */
                .flags = (r->flags & ~(ESTPIPE_FLAG_IPC_LOST | ESTPIPE_FLAG_NET_LOST | ESTPIPE_FLAG_TOKENS)) |
                         (delivered && r->has_tokens ? ESTPIPE_FLAG_TOKENS : 0),
                .tokens = delivered && r->has_tokens ? r->tokens : 0,
                .period_ns = period_ns,
                .stream_start_ns = t0,
            };
            if (delivered) memcpy(slot.y, r->y, sizeof slot.y);
            slot.send_ns = estpipe_monotonic_ns();
            rc = estpipe_publish(pub, &slot, 0);
            if (rc == ESTPIPE_STOPPED) {
                kind = ESTPIPE_SLOT_ABORT;
                break;
            }
            if (rc != ESTPIPE_OK) {
                fprintf(stderr, ME ": error: slot k = %u of node %u: %s\n", k, m,
                        rc == ESTPIPE_GAVE_UP ? "the runner is gone" : estpipe_last_error());
                status = 1;
                kind = ESTPIPE_SLOT_ABORT;
                break;
            }
            last_sent[m] = k;
            sent++;
        }
        if (kind == ESTPIPE_SLOT_ABORT) break;
        estpipe_instant_done(pub);
    }
    /* Every node's stream ends with its own marker (seq = k = its last instant sent). */
    for (uint8_t m = 0; m < header.nodes; m++) {
        estpipe_Slot end = {
            .version = ESTPIPE_WIRE_VERSION,
            .kind = kind,
            .stream_id = stream_id,
            .seq = last_sent[m],
            .k = last_sent[m],
            .node = m,
            .nodes = header.nodes,
            .period_ns = period_ns,
            .stream_start_ns = t0,
        };
        rc = estpipe_publish(pub, &end, 5000);
        if (rc != ESTPIPE_OK)
            fprintf(stderr, ME ": %s marker of node %u not delivered: %s\n",
                    kind == ESTPIPE_SLOT_END ? "END" : "ABORT", m,
                    rc == ESTPIPE_GAVE_UP ? "gave up after 5 s" : estpipe_last_error());
    }
    estpipe_instant_done(pub);
    /* The runner reads the tail from our memory: stay until it has detached (up to 5 s). */
    estpipe_publisher_close(pub, 5000);
    fprintf(stderr, ME ": published %zu slots of %u instants (%zu lost slots not sent)%s\n", sent,
            last_k, lost, kind == ESTPIPE_SLOT_ABORT ? ", aborted" : "");
    free(rows);
    return status;
}
