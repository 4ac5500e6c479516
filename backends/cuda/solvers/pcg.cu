/* Jacobi-preconditioned conjugate gradients on the device: the kernels of one iteration, launched
 * in a fixed order (runtime/solve/device.py, DevicePCG) and captured once as a CUDA graph, so an
 * iteration costs launches, not Python. Scalars (r.z, p.Ap, r.r) stay in a small device array s.
 *
 * Every sum is in a fixed order: a row's products by its lanes then a shuffle tree, a dot product by
 * grid-stride partial sums, a shared-memory tree per block and one block over the block sums. The
 * launch shapes depend on the sizes only, so a solve gives the same bits run after run (no atomics).
 *
 * Compiled with -DTM_HOST_SHIM this file is C99 for the host (one block of one thread): the checks
 * without a GPU run the same iteration.
 *
 * s[0] = r.z, s[1] = p.Ap, s[2] = the new r.z, s[3] = r.r (all of the current iterate).
 */
#ifdef TM_HOST_SHIM
#define TM_KERNEL void
#define TM_SHARED static
#define TM_SYNC()
#define TM_THREAD 0
#define TM_BLOCK 0
#define TM_BLOCK_THREADS 1
#define TM_GRID_THREADS 1
#define TM_ROW_LANES 1
#define TM_SHUFFLE_DOWN(value, offset) (value)
#else
#define restrict __restrict__
#define TM_KERNEL extern "C" __global__ void
#define TM_SHARED __shared__
#define TM_SYNC() __syncthreads()
#define TM_THREAD ((long)threadIdx.x)
#define TM_BLOCK ((long)blockIdx.x)
#define TM_BLOCK_THREADS 256
#define TM_GRID_THREADS ((long)blockDim.x * gridDim.x)
#define TM_ROW_LANES 8
#define TM_SHUFFLE_DOWN(value, offset) __shfl_down_sync(0xffffffffu, (value), (offset), TM_ROW_LANES)
#endif
#define TM_FIRST (TM_BLOCK * TM_BLOCK_THREADS + TM_THREAD)

/* y = A x (CSR, n rows): TM_ROW_LANES consecutive threads per row, every thread of the grid running
   the same number of rounds (the shuffle needs all its lanes). */
TM_KERNEL tm_spmv(long n, const int *restrict indptr, const int *restrict indices, const double *restrict data,
                  const double *restrict x, double *restrict y)
{
    const long lane = TM_FIRST % TM_ROW_LANES;
    const long groups = TM_GRID_THREADS / TM_ROW_LANES;
    const long rounds = (n + groups - 1) / groups;
    for (long round = 0; round < rounds; ++round) {
        const long row = TM_FIRST / TM_ROW_LANES + round * groups;
        double sum = 0.0;
        if (row < n)
            for (long k = indptr[row] + lane; k < indptr[row + 1]; k += TM_ROW_LANES)
                sum += data[k] * x[indices[k]];
        for (int offset = TM_ROW_LANES / 2; offset > 0; offset /= 2)
            sum += TM_SHUFFLE_DOWN(sum, offset);
        if (lane == 0 && row < n)
            y[row] = sum;
    }
}

/* The block's sum of value (every thread of the block calls it). */
static
#ifndef TM_HOST_SHIM
__device__
#endif
double tm_block_sum(double value)
{
    TM_SHARED double cache[TM_BLOCK_THREADS];
    cache[TM_THREAD] = value;
    TM_SYNC();
    for (int half = TM_BLOCK_THREADS / 2; half > 0; half /= 2) {
        if (TM_THREAD < half)
            cache[TM_THREAD] += cache[TM_THREAD + half];
        TM_SYNC();
    }
    const double sum = cache[0];
    TM_SYNC();
    return sum;
}

/* partial[block] = the block's share of a.b. */
TM_KERNEL tm_dot_partial(long n, const double *restrict a, const double *restrict b, double *restrict partial)
{
    double ab = 0.0;
    for (long i = TM_FIRST; i < n; i += TM_GRID_THREADS)
        ab += a[i] * b[i];
    ab = tm_block_sum(ab);
    if (TM_THREAD == 0)
        partial[TM_BLOCK] = ab;
}

/* partial[block] = the block's share of a.b, partial[blocks + block] its share of a.a. */
TM_KERNEL tm_dot2_partial(long n, const double *restrict a, const double *restrict b, long blocks,
                          double *restrict partial)
{
    double ab = 0.0, aa = 0.0;
    for (long i = TM_FIRST; i < n; i += TM_GRID_THREADS) {
        ab += a[i] * b[i];
        aa += a[i] * a[i];
    }
    ab = tm_block_sum(ab);
    aa = tm_block_sum(aa);
    if (TM_THREAD == 0) {
        partial[TM_BLOCK] = ab;
        partial[blocks + TM_BLOCK] = aa;
    }
}

/* s[slot] = the sum of partial[0 .. blocks) and, when pairs = 2, s[slot + 1] = the sum of the next
   blocks entries (one block). */
TM_KERNEL tm_dot_finish(long blocks, long pairs, const double *restrict partial, double *restrict s, long slot)
{
    for (long k = 0; k < pairs; ++k) {
        double sum = 0.0;
        for (long i = TM_THREAD; i < blocks; i += TM_BLOCK_THREADS)
            sum += partial[k * blocks + i];
        sum = tm_block_sum(sum);
        if (TM_THREAD == 0)
            s[slot + k] = sum;
    }
}

/* alpha = s[0] / s[1]; x += alpha p; r -= alpha Ap; z = r / diagonal. */
TM_KERNEL tm_update_xrz(long n, const double *restrict s, const double *restrict p, const double *restrict Ap,
                        const double *restrict inverse_diagonal, double *restrict x, double *restrict r,
                        double *restrict z)
{
    const double alpha = s[0] / s[1];
    for (long i = TM_FIRST; i < n; i += TM_GRID_THREADS) {
        x[i] += alpha * p[i];
        r[i] -= alpha * Ap[i];
        z[i] = inverse_diagonal[i] * r[i];
    }
}

/* beta = s[2] / s[0]; p = z + beta p. */
TM_KERNEL tm_update_p(long n, const double *restrict s, const double *restrict z, double *restrict p)
{
    const double beta = s[2] / s[0];
    for (long i = TM_FIRST; i < n; i += TM_GRID_THREADS)
        p[i] = z[i] + beta * p[i];
}

/* s[0] = s[2] (one thread, after every thread of tm_update_p has read s[0]). */
TM_KERNEL tm_shift(double *restrict s)
{
    if (TM_FIRST == 0)
        s[0] = s[2];
}
