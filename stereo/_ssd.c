/*
 * SSD block-matching scan for stereo/block_matching.py (reference ch. 5,
 * eq. 5.1), plain C99 called through ctypes: the kernel needs no Python or
 * numpy headers (only the empty module at the end, built by setup.py, uses
 * Python.h, so that `import stereo._ssd` locates the library).
 *
 * One fused pass per row band. For every disparity d the squared differences
 * of the left row and the right row shifted by d are summed over the window
 * incrementally: column sums (one per column and disparity) move down one row
 * at a time, and a running window sum moves along the row, so each pixel and
 * disparity costs O(1) whatever the window. Disparities are the innermost,
 * contiguous axis so the compiler vectorises across them. Per left pixel the
 * kernel keeps the best cost, the best outside d* - 1 .. d* + 1 (uniqueness)
 * and the costs at d* - 1 and d* + 1 (parabola); per right pixel the best
 * cost (left-right check). All arithmetic is integer and reproduces the numpy
 * path of block_matching.py bit for bit:
 *
 *   sq(y, x, d) = sum over planes p of (Lp[p, y, x] - R[p, y, clamp(x - d, 0, W - 1)])^2
 *   sum         = window sum of sq, rows reflected at the image edges and
 *                 columns reflected at 0 and W + D (OpenCV BORDER_REFLECT)
 *   cost        = sum >> rshift[k]            (scale == NULL)
 *               = (int32) (sum * scale[k])    (otherwise; truncation)
 *   encoded     = (cost << nb) | d, INT32_MAX where x < d.
 *
 * Each row is then decided (sub-pixel parabola, uniqueness, left-right check,
 * texture) in float32 exactly as block_matching._decide does it in numpy.
 *
 * On x86-64 an AVX2 build of the whole scan is chosen at run time when the
 * CPU has it; LUMIGRAPH_SSD_BASELINE=1 in the environment forces the
 * portable build (the tests compare both with numpy).
 */
#include <stdint.h>
#include <stdlib.h>
#include <math.h>
#include <string.h>

#define BIG INT32_MAX
#define MAXWIN 4
#define RB 8

/* x86-64 with GCC or Clang: an AVX2 build of the scan beside the baseline
 * one, chosen at run time (the library is built on one machine and may run
 * on another of the same kind). */
#if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__)
#define HAVE_AVX2_PATH 1
#include <immintrin.h>
#endif

static inline int reflect(int i, int n)
{
    if (i < 0)
        return -i - 1;
    if (i >= n)
        return 2 * n - i - 1;
    return i;
}

/* col[c][d] += sq(row, c, d) for c in [0, nc), summed over the nch planes
 * (lplane, rplane elements apart) */
static inline void add_row(uint32_t *restrict col, int dp, int nc, int D,
                           const uint16_t *restrict lrow, const uint16_t *restrict rrev, int roff,
                           int nch, int64_t lplane, int64_t rplane)
{
    for (int c = 0; c < nc; c++) {
        uint32_t *restrict cc = col + (size_t)c * dp;
        for (int ch = 0; ch < nch; ch++) {
            const int32_t lv = lrow[ch * lplane + c];
            const uint16_t *restrict rv = rrev + ch * rplane + (roff - c);
            for (int d = 0; d < D; d++) {
                const int32_t t = lv - (int32_t)rv[d];
                cc[d] += (uint32_t)(t * t);
            }
        }
    }
}

/* col[c][d] += sq(in, c, d) - sq(out, c, d) */
static inline void move_row(uint32_t *restrict col, int dp, int nc, int D,
                            const uint16_t *restrict lin, const uint16_t *restrict rin,
                            const uint16_t *restrict lout, const uint16_t *restrict rout, int roff,
                            int nch, int64_t lplane, int64_t rplane)
{
    for (int c = 0; c < nc; c++) {
        uint32_t *restrict cc = col + (size_t)c * dp;
        for (int ch = 0; ch < nch; ch++) {
            const int32_t a = lin[ch * lplane + c], b = lout[ch * lplane + c];
            const uint16_t *restrict ra = rin + ch * rplane + (roff - c);
            const uint16_t *restrict rb = rout + ch * rplane + (roff - c);
            for (int d = 0; d < D; d++) {
                const int32_t t = a - (int32_t)ra[d];
                const int32_t u = b - (int32_t)rb[d];
                cc[d] += (uint32_t)(t * t) - (uint32_t)(u * u);
            }
        }
    }
}

#ifdef HAVE_AVX2_PATH
/* move_row with 16-bit differences: one vpmaddwd of the interleaved pairs
 * (t, u) and (t, -u) gives t^2 - u^2 for 8 disparities (|t|, |u| <= 1020 fit
 * int16; the 64-bit lane permute first keeps the disparities in order). The
 * planes are summed in registers, so each column sum is loaded and stored
 * once per row whatever nch. */
__attribute__((target("avx2"))) static void move_row_avx2(
    uint32_t *restrict col, int dp, int nc, int D, const uint16_t *restrict lin,
    const uint16_t *restrict rin, const uint16_t *restrict lout,
    const uint16_t *restrict rout, int roff, int nch, int64_t lplane, int64_t rplane)
{
    for (int c = 0; c < nc; c++) {
        uint32_t *restrict cc = col + (size_t)c * dp;
        int d = 0;
        for (; d + 16 <= D; d += 16) {
            __m256i lo = _mm256_setzero_si256(), hi = _mm256_setzero_si256();
            for (int ch = 0; ch < nch; ch++) {
                const __m256i va = _mm256_set1_epi16((short)lin[ch * lplane + c]);
                const __m256i vb = _mm256_set1_epi16((short)lout[ch * lplane + c]);
                const uint16_t *ra = rin + ch * rplane + (roff - c);
                const uint16_t *rb = rout + ch * rplane + (roff - c);
                const __m256i x = _mm256_permute4x64_epi64(
                    _mm256_loadu_si256((const __m256i *)(ra + d)), 0xD8);
                const __m256i y = _mm256_permute4x64_epi64(
                    _mm256_loadu_si256((const __m256i *)(rb + d)), 0xD8);
                const __m256i t = _mm256_sub_epi16(va, x);
                const __m256i u = _mm256_sub_epi16(vb, y);
                const __m256i nu = _mm256_sub_epi16(y, vb);
                lo = _mm256_add_epi32(lo, _mm256_madd_epi16(_mm256_unpacklo_epi16(t, u),
                                                            _mm256_unpacklo_epi16(t, nu)));
                hi = _mm256_add_epi32(hi, _mm256_madd_epi16(_mm256_unpackhi_epi16(t, u),
                                                            _mm256_unpackhi_epi16(t, nu)));
            }
            __m256i *p0 = (__m256i *)(cc + d), *p1 = (__m256i *)(cc + d + 8);
            _mm256_storeu_si256(p0, _mm256_add_epi32(_mm256_loadu_si256(p0), lo));
            _mm256_storeu_si256(p1, _mm256_add_epi32(_mm256_loadu_si256(p1), hi));
        }
        for (; d < D; d++) {
            for (int ch = 0; ch < nch; ch++) {
                const int32_t t = lin[ch * lplane + c] - (int32_t)rin[ch * rplane + roff - c + d];
                const int32_t u = lout[ch * lplane + c] - (int32_t)rout[ch * rplane + roff - c + d];
                cc[d] += (uint32_t)(t * t) - (uint32_t)(u * u);
            }
        }
    }
}
#endif

/* Decision for one row, float32 arithmetic in the order numpy evaluates
 * block_matching._decide (so both paths agree bit for bit; this file is
 * compiled without floating-point contraction). */
typedef struct {
    int D, nb, subpixel, lr_tolerance, unique_test, npick;
    float u1;         /* 1 + uniqueness */
    float dist_var;   /* distinct * noise variance */
    float two_var;    /* 2 * noise variance */
    float unit;
    const int32_t *sides; /* npick candidate window sides */
} decide_t;

static void decide_row(const decide_t *p, int W, const int32_t *best, const int32_t *em,
                       const int32_t *ep, const int32_t *second, const int32_t *rrev,
                       const uint8_t *pick, const float *vpick, float *disp, float *cost,
                       int64_t *counts)
{
    const int nb = p->nb;
    const int32_t low = (1 << nb) - 1;
    for (int x = 0; x < W; x++) {
        const int32_t b = best[x];
        if (b == BIG) {
            disp[x] = NAN;
            cost[x] = NAN;
            continue;
        }
        const int bd = b & low;
        const float bc = (float)(b >> nb);
        float d = (float)bd;
        if (p->subpixel && bd > 0 && bd < p->D - 1 && em[x] != BIG && ep[x] != BIG) {
            const float cm = (float)(em[x] >> nb), cp = (float)(ep[x] >> nb);
            const float curv = (cm - 2.0f * bc) + cp;
            if (curv > 0) {
                float delta = (0.5f * (cm - cp)) / curv;
                delta = delta < -0.5f ? -0.5f : (delta > 0.5f ? 0.5f : delta);
                d = d + delta;
            }
        }
        int consistent = 1;
        if (p->lr_tolerance >= 0) {
            const int xr = x - (bd < x ? bd : x);
            const int back = rrev[W - 1 - xr] & low;
            consistent = abs(back - bd) <= p->lr_tolerance;
        }
        int unique = 1;
        if (p->unique_test) {
            const int32_t s = second[x];
            if (s != BIG) {
                const float sc = (float)(s >> nb);
                float margin = 0.0f;
                if (p->dist_var != 0.0f) {
                    const int k = pick[x] < p->npick ? pick[x] : p->npick - 1;
                    const float n = (float)p->sides[k] * (float)p->sides[k];
                    margin = (p->dist_var * sqrtf(8.0f / n)) * p->unit;
                    if (vpick[x] < p->two_var)
                        margin = 3.0f * margin;
                }
                unique = (sc > bc * p->u1) && (sc - bc > margin);
            }
        }
        const int textured = pick[x] < p->npick;
        /* branch-free: the three tests disagree from pixel to pixel */
        counts[0] += !textured;
        counts[1] += textured & !unique;
        counts[2] += textured & unique & !consistent;
        disp[x] = textured & unique & consistent ? d : NAN;
        cost[x] = bc / p->unit;
    }
}

/*
 * Lp     nch planes (lplane elements apart) of H x lstride uint16: left image
 *        with D reflected columns on its right (lstride >= W + D); nch = 1
 *        (luma) or 3 (R, G, B, squared differences summed).
 * Rrev   nch planes (rplane apart) of H x rstride uint16: each row of the right image padded with D - 1
 *        replicated columns on its left and D on its right (length
 *        P = W + 2D - 1 <= rstride), then reversed, so that
 *        R[clamp(c - d)] = Rrev[P - D - c + d], increasing in d.
 * wins   nwin odd window sides (nwin <= MAXWIN); cwin H x W window index per
 *        pixel (NULL when nwin == 1).
 * pick   H x W index of the textured candidate window (npick = none), vpick
 *        H x W float32 its variance (may be NULL when distinct is 0).
 * out    disp, cost: H x W float32, rows y0 .. y1 - 1 written; counts[3]
 *        (no texture, not unique, left-right) incremented.
 * Returns 0, or -1 on bad arguments / out of memory.
 */
#define MATCH_ARGS                                                                           \
    const uint16_t *Lp, int lstride, const uint16_t *Rrev, int rstride, int nch,              \
        int64_t lplane, int64_t rplane, int H, int W, int D,                                   \
        int y0, int y1, int nwin, const int32_t *wins, const uint8_t *cwin,                    \
        const int32_t *rshift, const double *scale, int nb, const uint8_t *pick, int npick,    \
        const int32_t *sides, const float *vpick, int subpixel, int lr_tolerance,              \
        int unique_test, double u1, double dist_var, double two_var, double unit, float *disp, \
        float *cost, int64_t *counts
#define MATCH_CALL                                                                            \
    Lp, lstride, Rrev, rstride, nch, lplane, rplane, H, W, D, y0, y1, nwin, wins, cwin, rshift, scale, nb, pick,    \
        npick, sides, vpick, subpixel, lr_tolerance, unique_test, u1, dist_var, two_var, unit, \
        disp, cost, counts

static inline __attribute__((always_inline)) int match_body(MATCH_ARGS, int avx2)
{
    if (nch < 1 || nch > 4 || nwin < 1 || nwin > MAXWIN || D < 1 || W < 1 || y0 < 0 || y1 > H || y0 >= y1 || npick < 1)
        return -1;
    const int wp = W + D;           /* width of the numpy path's diff array */
    const int P = W + 2 * D - 1;    /* padded right row */
    const int roff = P - D;
    int half[MAXWIN], hmax = 0;
    for (int k = 0; k < nwin; k++) {
        if (wins[k] < 1 || wins[k] % 2 == 0 || wins[k] / 2 >= H || wins[k] / 2 >= wp)
            return -1;
        half[k] = wins[k] / 2;
        if (half[k] > hmax)
            hmax = half[k];
    }
    const decide_t dp_ = {D, nb, subpixel, lr_tolerance, unique_test, npick, (float)u1,
                          (float)dist_var, (float)two_var, (float)unit, sides};
    const int nc = W + hmax < wp ? W + hmax : wp;
    const int dp = (D + 15) & ~15;
    uint32_t *col = malloc(sizeof(uint32_t) * (size_t)dp * ((size_t)nc * nwin + nwin));
    int32_t *enc = malloc(sizeof(int32_t) * (size_t)dp);
    /* best, em, ep, second, then RB right-best accumulators */
    int32_t *rows = malloc(sizeof(int32_t) * (size_t)W * (4 + RB));
    if (!col || !enc || !rows) {
        free(col);
        free(enc);
        free(rows);
        return -1;
    }
    uint32_t *acc = col + (size_t)dp * nc * nwin;
    int32_t *best = rows, *em = rows + W, *ep = rows + 2 * W, *second = rows + 3 * W;
    int32_t *rrev = rows + 4 * W;

    for (int y = y0; y < y1; y++) {
        for (int k = 0; k < nwin; k++) {
            uint32_t *ck = col + (size_t)dp * nc * k;
            const int h = half[k];
            if (y == y0) {
                memset(ck, 0, sizeof(uint32_t) * (size_t)dp * nc);
                for (int r = y - h; r <= y + h; r++) {
                    const int rr = reflect(r, H);
                    add_row(ck, dp, nc, D, Lp + (size_t)rr * lstride, Rrev + (size_t)rr * rstride,
                            roff, nch, lplane, rplane);
                }
            } else {
                const int ri = reflect(y + h, H), ro = reflect(y - h - 1, H);
                const uint16_t *li = Lp + (size_t)ri * lstride, *lo = Lp + (size_t)ro * lstride;
                const uint16_t *rI = Rrev + (size_t)ri * rstride, *rO = Rrev + (size_t)ro * rstride;
#ifdef HAVE_AVX2_PATH
                if (avx2)
                    move_row_avx2(ck, dp, nc, D, li, rI, lo, rO, roff, nch, lplane, rplane);
                else
#endif
                    move_row(ck, dp, nc, D, li, rI, lo, rO, roff, nch, lplane, rplane);
            }
        }
        for (int x = 0; x < W * RB; x++)
            rrev[x] = BIG;
        for (int x = 0; x < W; x++) {
            const int n = x + 1 < D ? x + 1 : D; /* disparities 0 .. n - 1 have a partner */
            /* the right pixel x - d sees e[d]: reversed so that the index grows
             * with d, and spread over RB buffers by x mod RB, so that a buffer's
             * next update starts RB elements (a whole vector) further and
             * reloads what was stored as it was stored (store forwarding) */
            int32_t *restrict rb = rrev + (size_t)W * (x % RB) + (W - 1 - x);
            int32_t *restrict e = enc;
            int32_t b = BIG;
            if (nwin == 1 && !scale && x > 0 && n == D) {
                /* one window, away from the left edge: window sum, encoding, best
                 * and right best in one pass */
                uint32_t *restrict ak = acc;
                const uint32_t *restrict ci = col + (size_t)dp * reflect(x + half[0], wp);
                const uint32_t *restrict co = col + (size_t)dp * reflect(x - half[0] - 1, wp);
                const int sh = rshift[0];
                for (int d = 0; d < D; d++) {
                    const uint32_t a = ak[d] + ci[d] - co[d];
                    ak[d] = a;
                    const int32_t v = ((int32_t)(a >> sh) << nb) | d;
                    e[d] = v;
                    b = v < b ? v : b;
                    rb[d] = v < rb[d] ? v : rb[d];
                }
            } else {
                for (int k = 0; k < nwin; k++) {
                    const uint32_t *ck = col + (size_t)dp * nc * k;
                    uint32_t *restrict ak = acc + (size_t)dp * k;
                    const int h = half[k];
                    if (x == 0) {
                        memset(ak, 0, sizeof(uint32_t) * (size_t)dp);
                        for (int c = -h; c <= h; c++) {
                            const uint32_t *restrict cc = ck + (size_t)dp * reflect(c, wp);
                            for (int d = 0; d < D; d++)
                                ak[d] += cc[d];
                        }
                    } else {
                        const uint32_t *restrict ci = ck + (size_t)dp * reflect(x + h, wp);
                        const uint32_t *restrict co = ck + (size_t)dp * reflect(x - h - 1, wp);
                        for (int d = 0; d < D; d++)
                            ak[d] += ci[d] - co[d];
                    }
                }
                const int k0 = cwin ? cwin[(size_t)y * W + x] : 0;
                const int k = k0 < nwin ? k0 : 0;
                const uint32_t *restrict ak = acc + (size_t)dp * k;
                if (scale) {
                    const double s = scale[k];
                    for (int d = 0; d < n; d++) {
                        const int32_t v = ((int32_t)((double)ak[d] * s) << nb) | d;
                        e[d] = v;
                        b = v < b ? v : b;
                        rb[d] = v < rb[d] ? v : rb[d];
                    }
                } else {
                    const int sh = rshift[k];
                    for (int d = 0; d < n; d++) {
                        const int32_t v = ((int32_t)(ak[d] >> sh) << nb) | d;
                        e[d] = v;
                        b = v < b ? v : b;
                        rb[d] = v < rb[d] ? v : rb[d];
                    }
                }
            }
            const int bd = b & ((1 << nb) - 1);
            /* runner-up outside bd - 1 .. bd + 1: those three are raised to BIG
             * (codes are >= 0, so or-ing BIG gives BIG) in one full-width pass */
            int32_t s2 = BIG;
            for (int d = 0; d < n; d++) {
                const int32_t v = e[d] | ((uint32_t)(d - bd + 1) <= 2u ? BIG : 0);
                s2 = v < s2 ? v : s2;
            }
            best[x] = b;
            second[x] = s2;
            em[x] = bd > 0 ? e[bd - 1] : e[0];
            ep[x] = bd + 1 < n ? e[bd + 1] : (bd + 1 < D ? BIG : e[D - 1]);
        }
        for (int m = 1; m < RB; m++)
            for (int x = 0; x < W; x++)
                rrev[x] = rrev[(size_t)W * m + x] < rrev[x] ? rrev[(size_t)W * m + x] : rrev[x];
        const size_t o = (size_t)y * W;
        decide_row(&dp_, W, best, em, ep, second, rrev, pick + o, vpick ? vpick + o : NULL,
                   disp + o, cost + o, counts);
    }
    free(col);
    free(enc);
    free(rows);
    return 0;
}

static int match_baseline(MATCH_ARGS) { return match_body(MATCH_CALL, 0); }

#ifdef HAVE_AVX2_PATH
__attribute__((target("avx2"))) static int match_avx2(MATCH_ARGS)
{
    return match_body(MATCH_CALL, 1);
}
#endif

int lumigraph_ssd_match(MATCH_ARGS)
{
#ifdef HAVE_AVX2_PATH
    if (__builtin_cpu_supports("avx2") && !getenv("LUMIGRAPH_SSD_BASELINE"))
        return match_avx2(MATCH_CALL);
#endif
    return match_baseline(MATCH_CALL);
}

#ifdef LUMIGRAPH_PYMODULE
/* An empty module, so that the import system finds the built library
 * (`import stereo._ssd`); the kernel itself is called through ctypes. */
#include <Python.h>

static struct PyModuleDef ssd_module = {PyModuleDef_HEAD_INIT, "_ssd",
                                        "SSD block-matching scan (loaded with ctypes).", -1, NULL};

PyMODINIT_FUNC PyInit__ssd(void) { return PyModule_Create(&ssd_module); }
#endif
