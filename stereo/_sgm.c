/* Semi-global matching kernels (Hirschmüller 2008), called through ctypes
 * from lumigraph.stereo.hirschmuller2008.
 *
 * Plain C, no numpy headers: arrays are passed as pointers to C-contiguous
 * buffers. Every function has a numpy twin in hirschmuller2008.py that gives
 * the same integers; the tests compare them.
 *
 *   census:    9x7 (or any odd wx x wy <= 64 bits) census transform of a u8 image
 *   cost:      Hamming costs of the census codes, summed over a (2r+1)^2 window
 *   aggregate: the 8 (or 4) path costs L_r of eq. 13, summed into S (eq. 14)
 *   wta:       per pixel the best disparity, the sums around it, the runner-up
 *              outside best +- 1, and the right image's best (the left-right check)
 *
 * Path arithmetic is int16 (values stay below 8192 by the caller's check), so
 * that the inner loop over disparities vectorises with SSE2's signed min.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define BIG16 30000

/* The hot loops are compiled twice: for the machine's baseline and, on
 * x86 with GCC or clang, for AVX2 + POPCNT, picked at run time. Integer
 * arithmetic only, so both give the same results. */
#if (defined(__GNUC__) || defined(__clang__)) && (defined(__x86_64__) || defined(__i386__))
#define LG_FAST __attribute__((target("avx2,popcnt")))
#define LG_INLINE static inline __attribute__((always_inline))
static int fast_ok(void) {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("popcnt");
}
#else
#define LG_FAST
#define LG_INLINE static inline
static int fast_ok(void) { return 0; }
#endif

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : (v > hi ? hi : v); }

LG_INLINE int popcount64(uint64_t v) {
#if defined(__GNUC__) || defined(__clang__)
    return __builtin_popcountll(v);
#else
    v = v - ((v >> 1) & 0x5555555555555555ULL);
    v = (v & 0x3333333333333333ULL) + ((v >> 2) & 0x3333333333333333ULL);
    v = (v + (v >> 4)) & 0x0F0F0F0F0F0F0F0FULL;
    return (int)((v * 0x0101010101010101ULL) >> 56);
#endif
}

/* Census transform: bit k (raster order over the window, centre skipped) is
 * set when the neighbour is darker than the centre; pixels outside the image
 * take the nearest border pixel's value. */
LG_INLINE int census_body(const uint8_t *img, int H, int W, int wx, int wy, uint64_t *out) {
    int rx = wx / 2, ry = wy / 2, pw = W + 2 * rx;
    uint8_t *pad = (uint8_t *)malloc((size_t)pw * (H + 2 * ry));
    if (!pad) return 2;
    for (int y = 0; y < H + 2 * ry; y++) {
        const uint8_t *src = img + (size_t)clampi(y - ry, 0, H - 1) * W;
        uint8_t *dst = pad + (size_t)y * pw;
        for (int x = 0; x < pw; x++) dst[x] = src[clampi(x - rx, 0, W - 1)];
    }
    for (int y = 0; y < H; y++) {
        const uint8_t *c = img + (size_t)y * W;
        uint64_t *code = out + (size_t)y * W;
        for (int x = 0; x < W; x++) code[x] = 0;
        int bit = 0;
        for (int dy = -ry; dy <= ry; dy++) {
            const uint8_t *row = pad + (size_t)(y + ry + dy) * pw + rx;
            for (int dx = -rx; dx <= rx; dx++) {
                if (dx == 0 && dy == 0) continue;
                const uint8_t *nb = row + dx;
                for (int x = 0; x < W; x++) code[x] |= (uint64_t)(nb[x] < c[x]) << bit;
                bit++;
            }
        }
    }
    free(pad);
    return 0;
}

LG_FAST static int census_fast(const uint8_t *img, int H, int W, int wx, int wy, uint64_t *out) {
    return census_body(img, H, W, wx, wy, out);
}

static int census_plain(const uint8_t *img, int H, int W, int wx, int wy, uint64_t *out) {
    return census_body(img, H, W, wx, wy, out);
}

int lumigraph_sgm_census(const uint8_t *img, int H, int W, int wx, int wy, uint64_t *out) {
    if (wx * wy - 1 > 64 || wx % 2 == 0 || wy % 2 == 0) return 1;
    return fast_ok() ? census_fast(img, H, W, wx, wy, out) : census_plain(img, H, W, wx, wy, out);
}

/* cost[y][x][d] = sum over the (2r+1)^2 window around (x, y) of the Hamming
 * distance between left (yy, xx) and right (yy, xx - d), with yy clamped to
 * the image and xx clamped to [d, W-1] (the columns whose right pixel
 * exists); `invalid` where x < d (no right pixel at all). The Hamming rows
 * (W x D) of the 2r+1 rows in the window are kept in a ring. */
LG_INLINE void ham_row(const uint64_t *cl, const uint64_t *cr, int W, int D, uint8_t *ham) {
    for (int x = 0; x < W; x++) {
        uint8_t *h = ham + (size_t)x * D;
        int dmax = x < D - 1 ? x : D - 1;
        for (int d = 0; d <= dmax; d++) h[d] = (uint8_t)popcount64(cl[x] ^ cr[x - d]);
    }
}

LG_INLINE int cost_body(const uint64_t *cl, const uint64_t *cr, int H, int W, int D, int r,
                        int invalid, uint16_t *cost) {
    int n = 2 * r + 1;
    size_t row = (size_t)W * D;
    uint8_t *ring = (uint8_t *)calloc(row * n, 1);
    uint16_t *V = (uint16_t *)malloc(sizeof(uint16_t) * row);
    int *held = (int *)malloc(sizeof(int) * n);
    if (!ring || !V || !held) { free(ring); free(V); free(held); return 2; }
    for (int k = 0; k < n; k++) held[k] = -1;
    for (int y = 0; y < H; y++) {
        for (size_t i = 0; i < row; i++) V[i] = 0;
        for (int dy = -r; dy <= r; dy++) {
            int yy = clampi(y + dy, 0, H - 1);
            uint8_t *h = ring + row * (size_t)(yy % n);
            if (held[yy % n] != yy) {
                ham_row(cl + (size_t)yy * W, cr + (size_t)yy * W, W, D, h);
                held[yy % n] = yy;
            }
            for (size_t i = 0; i < row; i++) V[i] = (uint16_t)(V[i] + h[i]);
        }
        uint16_t *cy = cost + (size_t)y * row;
        for (int x = 0; x < W; x++) {
            uint16_t *c = cy + (size_t)x * D;
            /* d <= x - r and x + r <= W - 1: no clamping */
            int dreg = x - r;
            if (dreg > D - 1) dreg = D - 1;
            if (x + r <= W - 1) {
                /* window columns added one at a time: the loops over d vectorise */
                const uint16_t *v0 = V + (size_t)(x - r) * D;
                for (int d = 0; d <= dreg; d++) c[d] = v0[d];
                for (int dx = -r + 1; dx <= r; dx++) {
                    const uint16_t *v = V + (size_t)(x + dx) * D;
                    for (int d = 0; d <= dreg; d++) c[d] = (uint16_t)(c[d] + v[d]);
                }
            } else {
                dreg = -1;
            }
            for (int d = dreg < 0 ? 0 : dreg + 1; d < D; d++) {
                if (d > x) { c[d] = (uint16_t)invalid; continue; }
                int s = 0;
                for (int dx = -r; dx <= r; dx++) s += V[(size_t)clampi(x + dx, d, W - 1) * D + d];
                c[d] = (uint16_t)s;
            }
        }
    }
    free(ring); free(V); free(held);
    return 0;
}

LG_FAST static int cost_fast(const uint64_t *cl, const uint64_t *cr, int H, int W, int D, int r,
                             int invalid, uint16_t *cost) {
    return cost_body(cl, cr, H, W, D, r, invalid, cost);
}

static int cost_plain(const uint64_t *cl, const uint64_t *cr, int H, int W, int D, int r,
                      int invalid, uint16_t *cost) {
    return cost_body(cl, cr, H, W, D, r, invalid, cost);
}

int lumigraph_sgm_cost(const uint64_t *cl, const uint64_t *cr, int H, int W, int D, int r,
                       int invalid, uint16_t *cost) {
    if (D > W) {  /* columns never reached: d >= W is x < d everywhere */
        for (size_t i = 0; i < (size_t)H * W * D; i++) cost[i] = (uint16_t)invalid;
    }
    return fast_ok() ? cost_fast(cl, cr, H, W, D, r, invalid, cost)
                     : cost_plain(cl, cr, H, W, D, r, invalid, cost);
}

/* One step of eq. 13 for one pixel: cur[d] = C[d] + min(prev[d], prev[d+-1] + P1,
 * min(prev) + P2) - min(prev). prev/cur hold D + 2 entries, [0] and [D + 1]
 * sentinels (BIG16), the disparities at [1 .. D]. Returns min(cur). */
LG_INLINE int16_t path_step(const uint16_t *C, const int16_t *prev, int16_t mprev, int16_t *cur,
                                int D, int16_t P1, int16_t P2) {
    int16_t m = BIG16;
    int16_t cap = (int16_t)(mprev + P2);
    for (int d = 0; d < D; d++) {
        int16_t v = prev[d + 1];
        int16_t a = (int16_t)(prev[d] + P1), b = (int16_t)(prev[d + 2] + P1);
        v = v < a ? v : a;
        v = v < b ? v : b;
        v = v < cap ? v : cap;
        v = (int16_t)(C[d] + v - mprev);
        cur[d + 1] = v;
        m = v < m ? v : m;
    }
    return m;
}

LG_INLINE int16_t path_start(const uint16_t *C, int16_t *cur, int D) {
    int16_t m = BIG16;
    for (int d = 0; d < D; d++) {
        int16_t v = (int16_t)C[d];
        cur[d + 1] = v;
        m = v < m ? v : m;
    }
    return m;
}

static inline int16_t penalty2(int P1, int P2, int edge, int a, int b) {
    int p2 = P2;
    if (edge > 0) p2 = P2 * edge / (edge + abs(a - b));
    return (int16_t)(p2 < P1 ? P1 : p2);
}

/* S = sum over the paths of L_r (eq. 14). Forward pass (rows top to bottom,
 * columns left to right): from the left, up-left, up and up-right; the
 * backward pass mirrors them. npaths = 4 keeps the left/up/right/down paths. */
LG_INLINE int aggregate_body(const uint16_t *cost, const uint8_t *guide, int H, int W, int D,
                            int P1, int P2, int edge, int npaths, uint16_t *S) {
    size_t stride = (size_t)D + 2;
    /* per direction k (0: horizontal, 1..3: from the previous row with dx = -1, 0, +1):
       two rows of path costs (W x stride) and their minima */
    int16_t *buf = (int16_t *)malloc(sizeof(int16_t) * stride * (size_t)W * 6 + sizeof(int16_t) * stride * 2);
    int16_t *mins = (int16_t *)malloc(sizeof(int16_t) * (size_t)W * 6);
    uint16_t *acc = (uint16_t *)malloc(sizeof(uint16_t) * (size_t)D);
    if (!buf || !mins || !acc) { free(buf); free(mins); free(acc); return 2; }
    for (size_t i = 0; i < stride * (size_t)W * 6 + stride * 2; i++) buf[i] = BIG16;
    int16_t *hor[2] = {buf + stride * (size_t)W * 6, buf + stride * (size_t)W * 6 + stride};
    const int dxs[3] = {-1, 0, 1};
    int diag = npaths == 8;

    for (int pass = 0; pass < 2; pass++) {
        int sgn = pass == 0 ? 1 : -1; /* +1: forward */
        for (int y0 = 0; y0 < H; y0++) {
            int y = pass == 0 ? y0 : H - 1 - y0;
            int cur_row = y0 & 1, prev_row = cur_row ^ 1;
            int16_t hmin = 0;
            for (int x0 = 0; x0 < W; x0++) {
                int x = pass == 0 ? x0 : W - 1 - x0;
                const uint16_t *C = cost + ((size_t)y * W + x) * D;
                int g = guide[(size_t)y * W + x];
                /* horizontal: previous pixel (x - sgn, y) */
                int16_t *hc = hor[x0 & 1], *hp = hor[(x0 & 1) ^ 1];
                if (x0 == 0) hmin = path_start(C, hc, D);
                else hmin = path_step(C, hp, hmin, hc, D, (int16_t)P1,
                                      penalty2(P1, P2, edge, g, guide[(size_t)y * W + x - sgn]));
                for (int d = 0; d < D; d++) acc[d] = (uint16_t)hc[d + 1];
                /* from the previous row: (x - sgn*dx, y - sgn) */
                for (int k = 0; k < 3; k++) {
                    if (!diag && k != 1) continue;
                    int16_t *rows = buf + stride * (size_t)W * (2 * k);
                    int16_t *cur = rows + stride * ((size_t)W * cur_row + x);
                    int16_t *mcur = mins + (size_t)W * (2 * k + cur_row) + x;
                    int xp = x - sgn * dxs[k];
                    if (y0 == 0 || xp < 0 || xp >= W) {
                        *mcur = path_start(C, cur, D);
                    } else {
                        const int16_t *prev = rows + stride * ((size_t)W * prev_row + xp);
                        int16_t mp = mins[(size_t)W * (2 * k + prev_row) + xp];
                        *mcur = path_step(C, prev, mp, cur, D, (int16_t)P1,
                                          penalty2(P1, P2, edge, g, guide[(size_t)(y - sgn) * W + xp]));
                    }
                    for (int d = 0; d < D; d++) acc[d] = (uint16_t)(acc[d] + cur[d + 1]);
                }
                uint16_t *s = S + ((size_t)y * W + x) * D;
                if (pass == 0) for (int d = 0; d < D; d++) s[d] = acc[d];
                else for (int d = 0; d < D; d++) s[d] = (uint16_t)(s[d] + acc[d]);
            }
        }
    }
    free(buf); free(mins); free(acc);
    return 0;
}

LG_FAST static int aggregate_fast(const uint16_t *cost, const uint8_t *guide, int H, int W, int D,
                                  int P1, int P2, int edge, int npaths, uint16_t *S) {
    return aggregate_body(cost, guide, H, W, D, P1, P2, edge, npaths, S);
}

static int aggregate_plain(const uint16_t *cost, const uint8_t *guide, int H, int W, int D,
                           int P1, int P2, int edge, int npaths, uint16_t *S) {
    return aggregate_body(cost, guide, H, W, D, P1, P2, edge, npaths, S);
}

int lumigraph_sgm_aggregate(const uint16_t *cost, const uint8_t *guide, int H, int W, int D,
                            int P1, int P2, int edge, int npaths, uint16_t *S) {
    return fast_ok() ? aggregate_fast(cost, guide, H, W, D, P1, P2, edge, npaths, S)
                     : aggregate_plain(cost, guide, H, W, D, P1, P2, edge, npaths, S);
}

/* Winner-take-all over d <= min(x, D-1) (ties: the smaller d), the sums at
 * best - 1, best, best + 1 (-1 where outside the searchable range), the
 * runner-up outside best +- 1 (INT32_MAX when none) and, for every right
 * pixel xr, the d <= W-1-xr minimising S[y][xr + d][d] (ties: smaller d;
 * skipped when best_r is NULL). */
LG_INLINE int wta_body(const uint16_t *S, int H, int W, int D, int16_t *best, int32_t *sb,
                      int32_t *sm, int32_t *sp, int32_t *second, int16_t *best_r) {
    /* best_r NULL: the right image's search is skipped */
    for (int y = 0; y < H; y++) {
        for (int x = 0; x < W; x++) {
            const uint16_t *s = S + ((size_t)y * W + x) * D;
            int dmax = x < D - 1 ? x : D - 1;
            uint16_t v = s[0];
            for (int d = 1; d <= dmax; d++) v = s[d] < v ? s[d] : v;
            int b = 0;
            while (s[b] != v) b++;
            uint16_t lo = 0xFFFF, hi = 0xFFFF;
            for (int d = 0; d < b - 1; d++) lo = s[d] < lo ? s[d] : lo;
            for (int d = b + 2; d <= dmax; d++) hi = s[d] < hi ? s[d] : hi;
            int32_t sec = (b - 1 > 0 || b + 2 <= dmax) ? (lo < hi ? lo : hi) : INT32_MAX;
            size_t i = (size_t)y * W + x;
            best[i] = (int16_t)b;
            sb[i] = v;
            sm[i] = b > 0 ? s[b - 1] : -1;
            sp[i] = b < dmax ? s[b + 1] : -1;
            second[i] = sec;
        }
        /* right pixel xr: S[y][xr + d][d], a stride of D + 1 */
        if (!best_r) continue;
        const uint16_t *sy = S + (size_t)y * W * D;
        for (int xr = 0; xr < W; xr++) {
            int dmax = W - 1 - xr < D - 1 ? W - 1 - xr : D - 1;
            const uint16_t *s = sy + (size_t)xr * D;
            uint16_t v = 0xFFFF;
            for (int d = 0; d <= dmax; d++) v = s[(size_t)d * (D + 1)] < v ? s[(size_t)d * (D + 1)] : v;
            int b = 0;
            while (s[(size_t)b * (D + 1)] != v) b++;
            best_r[(size_t)y * W + xr] = (int16_t)b;
        }
    }
    return 0;
}

LG_FAST static int wta_fast(const uint16_t *S, int H, int W, int D, int16_t *best, int32_t *sb,
                            int32_t *sm, int32_t *sp, int32_t *second, int16_t *best_r) {
    return wta_body(S, H, W, D, best, sb, sm, sp, second, best_r);
}

static int wta_plain(const uint16_t *S, int H, int W, int D, int16_t *best, int32_t *sb,
                     int32_t *sm, int32_t *sp, int32_t *second, int16_t *best_r) {
    return wta_body(S, H, W, D, best, sb, sm, sp, second, best_r);
}

int lumigraph_sgm_wta(const uint16_t *S, int H, int W, int D, int16_t *best, int32_t *sb,
                      int32_t *sm, int32_t *sp, int32_t *second, int16_t *best_r) {
    return fast_ok() ? wta_fast(S, H, W, D, best, sb, sm, sp, second, best_r)
                     : wta_plain(S, H, W, D, best, sb, sm, sp, second, best_r);
}

/* The right image's disparity as the left pixels claim it (OpenCV's left-right
 * check): at each right pixel xr, the best d of the lowest-cost left pixel
 * (among those with ok set) whose winner lands there, ties to the smaller d;
 * -1 where none lands. */
int lumigraph_sgm_claims(const int16_t *best, const int32_t *sb, const uint8_t *ok, int H, int W,
                         int16_t *claim) {
    int32_t *cost = (int32_t *)malloc(sizeof(int32_t) * (size_t)W);
    if (!cost) return 2;
    for (int y = 0; y < H; y++) {
        int16_t *cl = claim + (size_t)y * W;
        for (int x = 0; x < W; x++) { cost[x] = INT32_MAX; cl[x] = -1; }
        for (int x = 0; x < W; x++) {
            size_t i = (size_t)y * W + x;
            if (!ok[i]) continue;
            int xr = x - best[i];
            if (xr < 0 || xr >= W) continue;
            if (sb[i] < cost[xr] || (sb[i] == cost[xr] && best[i] < cl[xr])) {
                cost[xr] = sb[i];
                cl[xr] = best[i];
            }
        }
    }
    free(cost);
    return 0;
}

#ifdef LUMIGRAPH_PYMODULE
/* An empty module, so that the import system finds the built library
 * (`import lumigraph.stereo._sgm`); the kernels are called through ctypes. */
#include <Python.h>

static struct PyModuleDef sgm_module = {PyModuleDef_HEAD_INIT, "_sgm",
                                        "Semi-global matching kernels (loaded with ctypes).", -1, NULL};

PyMODINIT_FUNC PyInit__sgm(void) { return PyModule_Create(&sgm_module); }
#endif
