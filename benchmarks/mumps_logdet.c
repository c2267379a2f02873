/* The log-determinant of a symmetric positive definite matrix by MUMPS (sequential library), for
 * benchmarks/factor_candidates.py, which compiles it against the system's MUMPS and runs it in a
 * process of its own.
 *
 *   mumps_logdet MATRIX ORDERING [PERM]
 *
 * MATRIX: int64 n, int64 nnz, then the lower triangle as nnz int32 row indices, nnz int32 column
 * indices (1-based) and nnz float64 values. ORDERING: MUMPS's ICNTL(7) (0 AMD, 2 AMF, 3 SCOTCH,
 * 4 PORD, 5 METIS, 6 QAMD, 7 MUMPS's automatic choice; 1 = the pivot order in PERM: n int32, the
 * 1-based position of each variable). Prints one JSON object: the ordering used, the analysis and
 * numeric factorization wall times, MUMPS's count of the elimination's flops (RINFOG(3)), the
 * factor's entries, the log-determinant (RINFOG(12) 2^INFOG(34), ICNTL(33)) and the peak RSS. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <math.h>
#include <time.h>
#include <sys/resource.h>
#include "dmumps_c.h"

#define ICNTL(I) icntl[(I) - 1]
#define INFOG(I) infog[(I) - 1]
#define RINFOG(I) rinfog[(I) - 1]

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* The failure as the one JSON object the caller reads, and the exit code. */
static void die(int code, const char *message, const char *detail) {
    printf("{\"error\": \"%s%s\"}\n", message, detail);
    exit(code);
}

static FILE *open_or_die(const char *path) {
    FILE *f = fopen(path, "rb");
    if (f == NULL)
        die(1, "cannot open ", path);
    return f;
}

static void *read_or_die(FILE *f, size_t size, size_t count, const char *what) {
    void *p = malloc(size * count);
    if (p == NULL || fread(p, size, count, f) != count)
        die(1, "cannot read ", what);
    return p;
}

/* One MUMPS phase (JOB = 1 analysis, 2 factorization); its error ends the program. */
static void run_job(DMUMPS_STRUC_C *id, int job, const char *phase) {
    id->job = job;
    dmumps_c(id);
    if (id->INFOG(1) < 0) {
        printf("{\"error\": \"MUMPS %s: INFOG(1) = %d, INFOG(2) = %d\"}\n", phase, id->INFOG(1), id->INFOG(2));
        exit(1);
    }
}

int main(int argc, char **argv) {
    if (argc < 3)
        die(2, "usage: mumps_logdet MATRIX ORDERING [PERM]", "");
    FILE *f = open_or_die(argv[1]);
    int ordering = atoi(argv[2]);
    int64_t *head = read_or_die(f, sizeof(int64_t), 2, "the header");
    int64_t n = head[0], nnz = head[1];
    int *irn = read_or_die(f, sizeof(int), nnz, "row indices");
    int *jcn = read_or_die(f, sizeof(int), nnz, "column indices");
    double *a = read_or_die(f, sizeof(double), nnz, "values");
    fclose(f);

    DMUMPS_STRUC_C id;
    id.comm_fortran = -987654;   /* USE_COMM_WORLD: the sequential library's stub */
    id.par = 1;
    id.sym = 1;                  /* symmetric positive definite */
    id.job = -1;
    dmumps_c(&id);
    id.n = (MUMPS_INT)n;
    id.nnz = nnz;
    id.irn = irn;
    id.jcn = jcn;
    id.a = a;
    id.ICNTL(1) = -1;
    id.ICNTL(2) = -1;
    id.ICNTL(3) = -1;
    id.ICNTL(4) = 0;
    id.ICNTL(7) = ordering;
    id.ICNTL(33) = 1;            /* the determinant */
    if (ordering == 1) {
        if (argc < 4)
            die(2, "ordering 1 needs PERM", "");
        FILE *g = open_or_die(argv[3]);
        id.perm_in = read_or_die(g, sizeof(int), n, "the pivot order");
        fclose(g);
    }
    double t0 = now();
    run_job(&id, 1, "analysis");
    double t1 = now();
    run_job(&id, 2, "factorization");
    double t2 = now();
    if (id.INFOG(12) > 0 || !(id.RINFOG(12) > 0.0)) {   /* negative pivots (INFOG(12)) or det <= 0 */
        printf("{\"error\": \"not positive definite: %d negative pivots\"}\n", id.INFOG(12));
        return 1;
    }
    double logdet = log(id.RINFOG(12)) + id.INFOG(34) * log(2.0);
    struct rusage usage;
    getrusage(RUSAGE_SELF, &usage);
    printf("{\"ordering_used\": %d, \"analyse\": %.6f, \"factor\": %.6f, \"flops\": %.17g, \"lnz\": %lld, "
           "\"logdet\": %.17g, \"peak_rss\": %lld}\n",
           id.INFOG(7), t1 - t0, t2 - t1, id.RINFOG(3), (long long)id.INFOG(29), logdet,
           (long long)usage.ru_maxrss * 1024);
    id.job = -2;
    dmumps_c(&id);
    return 0;
}
