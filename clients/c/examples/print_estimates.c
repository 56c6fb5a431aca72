/* Estimate subscriber example in C: prints k, x̂ and P of every estimate ipc-runner publishes,
 * as clients/python/examples/print_estimates.py does.
 *
 *     clients/c/build/print_estimates --prefix mine --idle-exit 2
 *
 * A subscriber that connects while the runner runs first gets the newest estimates (the
 * service keeps a history). --csv prints k,estimator,status,x_0..,p_0.. rows with 17
 * significant digits (every double read back exactly). --idle-exit S: once estimates came,
 * exit after S seconds without a new one (0 = never; before the first one it waits for ever,
 * since the runner and its publisher may be started minutes later). SIGINT ends it (exit 0).
 */
#define _POSIX_C_SOURCE 200809L

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "estpipe.h"

#define ME "print_estimates"

/* The estimator's name (zero-padded UTF-8), padded with spaces to `width`. */
static void print_name(const estpipe_Estimate *e, size_t width) {
    size_t n = strnlen((const char *)e->name, sizeof e->name);
    fwrite(e->name, 1, n, stdout);
    for (; n < width; n++) putchar(' ');
}

int main(int argc, char **argv) {
    const char *prefix = "estpipe";
    double idle_exit = 0.0;
    int csv = 0;
    for (int i = 1; i < argc; i++) {
        char *end = NULL;
        if (!strcmp(argv[i], "--csv")) {
            csv = 1;
        } else if (!strcmp(argv[i], "--prefix") && i + 1 < argc) {
            prefix = argv[++i];
        } else if (!strcmp(argv[i], "--idle-exit") && i + 1 < argc) {
            idle_exit = strtod(argv[++i], &end);
            if (*end || !(idle_exit >= 0 && idle_exit < 4e6)) {
                fprintf(stderr, ME ": error: --idle-exit %s is not seconds >= 0\n", argv[i]);
                return 2;
            }
        } else {
            fprintf(stderr, "usage: " ME " [--prefix P] [--idle-exit S] [--csv]\n");
            return 2;
        }
    }

    estpipe_subscriber *sub;
    if (estpipe_subscriber_open(prefix, &sub) != ESTPIPE_OK) {
        fprintf(stderr, ME ": error: %s\n", estpipe_last_error());
        return 1;
    }
    fprintf(stderr, "ready\n");

    int status = 0;
    uint64_t last = 0; /* when the last estimate came; the idle timer starts at the first */
    for (;;) {
        estpipe_Estimate e;
        int rc = estpipe_receive(sub, &e, 100);
        if (rc == ESTPIPE_TIMEOUT) {
            if (idle_exit > 0 && last && (estpipe_monotonic_ns() - last) / 1e9 > idle_exit) break;
            continue;
        }
        if (rc == ESTPIPE_STOPPED) break;
        if (rc != ESTPIPE_OK) {
            fprintf(stderr, ME ": error: %s\n", estpipe_last_error());
            status = 1;
            break;
        }
        last = estpipe_monotonic_ns();
        uint32_t nx = e.nx <= ESTPIPE_MAX_NX ? e.nx : ESTPIPE_MAX_NX;
        size_t np = (size_t)nx * (nx + 1) / 2;
        if (csv) {
            printf("%u,", e.k);
            print_name(&e, 0);
            printf(",%u", e.status);
            for (uint32_t j = 0; j < nx; j++) printf(",%.17g", e.x[j]);
            for (size_t j = 0; j < np; j++) printf(",%.17g", e.p[j]);
            putchar('\n');
        } else {
            printf("k %5u ", e.k);
            print_name(&e, 8);
            printf(" x̂ [");
            for (uint32_t j = 0; j < nx; j++) printf("%s%.6g", j ? ", " : "", e.x[j]);
            printf("]  P [");
            for (uint32_t i = 0; i < nx; i++) {
                printf("%s[", i ? ", " : "");
                for (uint32_t j = 0; j < nx; j++)
                    printf("%s%.6g", j ? ", " : "", e.p[estpipe_packed_index(nx, i, j)]);
                printf("]");
            }
            printf("]\n");
        }
    }
    fflush(stdout);
    estpipe_subscriber_close(sub);
    return status;
}
