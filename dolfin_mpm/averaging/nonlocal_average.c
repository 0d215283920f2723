/* Pair kernels of the non-local average (nonlocal_average.py): the search for the pairs, the
 * weights and the product, one pass over the pairs each.
 *
 * A pair list holds each unordered pair (i, j) once, in runs of equal i: run r holds the pairs
 * (row[r], j[k]), begin[r] <= k < begin[r + 1]. The weights are symmetric and the average
 * applies A = I + W + W^T. Positions are (n, gdim) row-major doubles, gdim 2 or 3.
 *
 * The loops stream the pairs through memory (~10^7 for 10^5 particles) and are bound by its
 * bandwidth: a run stores its i once, and the weights pass keeps only the pairs closer than r
 * for the products.
 */
#include <math.h>
#include <stdint.h>

enum { CUBIC = 0, CONSTANT = 1, GAUSSIAN = 2, WENDLAND = 3 };

/* With AVX-512 (a -march=native build on a processor that has it) the weights pass takes eight
 * pairs at a time: their positions gathered, the pairs closer than r compressed into the output
 * and their weights computed in the same registers. The scalar pass is latency bound at about
 * five cycles a pair (the gathers and the running count); this one runs 1.8 times faster on
 * the silo's pairs. Lane by lane it does the scalar code's IEEE operations in the same order,
 * so either build gives the same bits (the Gaussian weight, whose exp has no such vector
 * form, keeps the scalar pass). Indices times gdim must fit in int32 (n < 7e8 particles). */
#if defined(__AVX512F__) && defined(__AVX512VL__)
#define VECTOR_PAIRS 1
#include <immintrin.h>
#else
#define VECTOR_PAIRS 0
#endif

/* w(s) for s^2 = s2 < 1. */
static inline double weight(int32_t kind, double s2)
{
  if (kind == CUBIC)
  {
    const double s = sqrt(s2);
    return (1.0 - s) * (1.0 - s) * (1.0 + 2.0 * s); /* = 1 + s^2 (2s - 3), no cancellation */
  }
  if (kind == CONSTANT)
    return 1.0;
  if (kind == WENDLAND)
  {
    const double s = sqrt(s2), t = (1.0 - s) * (1.0 - s);
    return t * t * (1.0 + 4.0 * s);
  }
  return exp(-2.5 * s2);
}

#if VECTOR_PAIRS
/* w(s) of eight s^2 (any, beyond 1 too), as weight() computes each; not the Gaussian. */
static inline __m512d weight8(int32_t kind, __m512d s2)
{
  const __m512d one = _mm512_set1_pd(1.0);
  if (kind == CONSTANT)
    return one;
  const __m512d s = _mm512_sqrt_pd(s2), u = _mm512_sub_pd(one, s);
  if (kind == CUBIC) /* (1 - s) (1 - s) (1 + 2 s) */
    return _mm512_mul_pd(_mm512_mul_pd(u, u), _mm512_add_pd(one, _mm512_mul_pd(_mm512_set1_pd(2.0), s)));
  const __m512d t = _mm512_mul_pd(u, u); /* WENDLAND: t t (1 + 4 s), t = (1 - s)^2 */
  return _mm512_mul_pd(_mm512_mul_pd(t, t), _mm512_add_pd(one, _mm512_mul_pd(_mm512_set1_pd(4.0), s)));
}

/* The pairs (a, j[k]), k0 <= k < k1, closer than r, appended with their weights to j_near and w
 * from `count` on; returns the new count. Room for them is there (count + k1 - k0 <= capacity);
 * a whole vector is stored where eight more fit, else only the kept lanes. */
static inline int64_t near_run8(int32_t kind, int32_t gdim, const double *restrict x_a, const int32_t *restrict j,
                                int64_t k0, int64_t k1, const double *restrict x, double inv_r2, int64_t count,
                                int64_t capacity, int32_t *restrict j_near, double *restrict w)
{
  const __m512d scale = _mm512_set1_pd(inv_r2), one = _mm512_set1_pd(1.0);
  const __m256i stride = _mm256_set1_epi32(gdim);
  for (int64_t k = k0; k < k1; k += 8)
  {
    const __mmask8 live = k1 - k >= 8 ? 0xff : (__mmask8)((1u << (k1 - k)) - 1u);
    const __m256i jv = _mm256_maskz_loadu_epi32(live, j + k);
    const __m256i at = _mm256_mullo_epi32(jv, stride);
    __m512d d2 = _mm512_setzero_pd();
    for (int32_t c = 0; c < gdim; ++c)
    {
      const __m512d x_b = _mm512_mask_i32gather_pd(_mm512_setzero_pd(), live, at, x + c, 8);
      const __m512d d = _mm512_sub_pd(_mm512_set1_pd(x_a[c]), x_b);
      d2 = _mm512_add_pd(d2, _mm512_mul_pd(d, d));
    }
    const __m512d s2 = _mm512_mul_pd(d2, scale);
    const __mmask8 near = _mm512_mask_cmp_pd_mask(live, s2, one, _CMP_LT_OQ);
    const __m512d wv = weight8(kind, s2);
    if (count + 8 <= capacity)
    {
      _mm512_storeu_pd(w + count, _mm512_maskz_compress_pd(near, wv));
      _mm256_storeu_si256((__m256i *)(j_near + count), _mm256_maskz_compress_epi32(near, jv));
    }
    else
    {
      _mm512_mask_compressstoreu_pd(w + count, near, wv);
      _mm256_mask_compressstoreu_epi32(j_near + count, near, jv);
    }
    count += __builtin_popcount(near);
  }
  return count;
}
#endif

/* Two passes: the pairs closer than r from their squared distances, then the weights of the
 * kept ones (contiguous: no gathers, and no root for the pairs dropped); with VECTOR_PAIRS one
 * (near_run8). At most `capacity` are kept: counts[0] = the runs kept, counts[1] = the pairs
 * closer than r, which exceeds `capacity` when the output was too short (then only counted from
 * the run that did not fit). */
static inline void weights_of(int32_t kind, int32_t gdim, int64_t runs, const int32_t *restrict row,
                              const int64_t *restrict begin, const int32_t *restrict j,
                              const double *restrict x, double inv_r, int64_t capacity,
                              int32_t *restrict row_near, int64_t *restrict begin_near,
                              int32_t *restrict j_near, double *restrict w, int64_t *counts)
{
  const double inv_r2 = inv_r * inv_r;
  int64_t runs_near = 0, count = 0;
  for (int64_t r = 0; r < runs; ++r)
  {
    const double *x_a = x + (int64_t)row[r] * gdim;
    const int64_t first = count;
    if (count + begin[r + 1] - begin[r] > capacity) /* may not fit: count only, from here on */
    {
      for (int64_t q = r; q < runs; ++q)
      {
        const double *x_q = x + (int64_t)row[q] * gdim;
        for (int64_t k = begin[q]; k < begin[q + 1]; ++k)
        {
          const double *x_b = x + (int64_t)j[k] * gdim;
          double d2 = 0.0;
          for (int32_t c = 0; c < gdim; ++c)
            d2 += (x_q[c] - x_b[c]) * (x_q[c] - x_b[c]);
          count += d2 * inv_r2 < 1.0;
        }
      }
      counts[0] = runs_near;
      counts[1] = count > capacity ? count : capacity + 1;
      return;
    }
#if VECTOR_PAIRS
    if (kind != GAUSSIAN)
      count = near_run8(kind, gdim, x_a, j, begin[r], begin[r + 1], x, inv_r2, count, capacity, j_near, w);
    else
#endif
      for (int64_t k = begin[r]; k < begin[r + 1]; ++k)
      {
        const double *x_b = x + (int64_t)j[k] * gdim;
        double d2 = 0.0;
        for (int32_t c = 0; c < gdim; ++c)
          d2 += (x_a[c] - x_b[c]) * (x_a[c] - x_b[c]);
        const double s2 = d2 * inv_r2;
        /* Written every time, kept (the count advances) only within the radius: no branch. */
        j_near[count] = j[k];
        w[count] = s2;
        count += s2 < 1.0;
      }
    if (count > first)
    {
      row_near[runs_near] = row[r];
      begin_near[runs_near++] = first;
    }
  }
  begin_near[runs_near] = count;
  if (!VECTOR_PAIRS || kind == GAUSSIAN) /* else weighted as kept */
    for (int64_t k = 0; k < count; ++k)
      w[k] = weight(kind, w[k]);
  counts[0] = runs_near;
  counts[1] = count;
}

/* The pairs of the list (runs, row, begin, j) closer than r, in their order, to the list
 * (counts[0] runs, row_near, begin_near, j_near) of at most `capacity` pairs, with their weights
 * w(|x_i - x_j| / r) in w; counts as weights_of leaves them. One loop per weight and dimension
 * (2 or 3), each with both inlined. (Accumulating A volume in the same loop made it slower
 * than a second pass.) */
void pair_weights(int64_t runs, const int32_t *row, const int64_t *begin, const int32_t *j,
                  int32_t gdim, const double *x, double inv_r, int32_t kind, int64_t capacity,
                  int32_t *row_near, int64_t *begin_near, int32_t *j_near, double *w, int64_t *counts)
{
#define WEIGHTS_OF(kind, gdim)                                                                      \
  weights_of(kind, gdim, runs, row, begin, j, x, inv_r, capacity, row_near, begin_near, j_near, w, counts)
  if (gdim == 2)
    kind == CUBIC      ? WEIGHTS_OF(CUBIC, 2)
    : kind == CONSTANT ? WEIGHTS_OF(CONSTANT, 2)
    : kind == WENDLAND ? WEIGHTS_OF(WENDLAND, 2)
                       : WEIGHTS_OF(GAUSSIAN, 2);
  else
    kind == CUBIC      ? WEIGHTS_OF(CUBIC, 3)
    : kind == CONSTANT ? WEIGHTS_OF(CONSTANT, 3)
    : kind == WENDLAND ? WEIGHTS_OF(WENDLAND, 3)
                       : WEIGHTS_OF(GAUSSIAN, 3);
#undef WEIGHTS_OF
}

/* out = A v = v + (W + W^T) v; v and out of length n. A row's own sum stays in two registers
 * (no chain of additions through memory); the other ends are scattered. */
void pair_apply(int64_t n, int64_t runs, const int32_t *restrict row, const int64_t *restrict begin,
                const int32_t *restrict j, const double *restrict w, const double *restrict v,
                double *restrict out)
{
  for (int64_t a = 0; a < n; ++a)
    out[a] = v[a];
  for (int64_t r = 0; r < runs; ++r)
  {
    const int32_t a = row[r];
    const double v_a = v[a];
    double sum0 = 0.0, sum1 = 0.0;
    int64_t k = begin[r];
    for (; k + 1 < begin[r + 1]; k += 2)
    {
      sum0 += w[k] * v[j[k]];
      sum1 += w[k + 1] * v[j[k + 1]];
      out[j[k]] += w[k] * v_a;
      out[j[k + 1]] += w[k + 1] * v_a;
    }
    if (k < begin[r + 1])
    {
      sum0 += w[k] * v[j[k]];
      out[j[k]] += w[k] * v_a;
    }
    out[a] += sum0 + sum1;
  }
}

/* out = A v for two fields at once, v and out (n, 2) row-major (the two fields side by side:
 * a pair reads and writes one place for both); each field summed as pair_apply sums it. */
void pair_apply2(int64_t n, int64_t runs, const int32_t *restrict row, const int64_t *restrict begin,
                 const int32_t *restrict j, const double *restrict w, const double *restrict v,
                 double *restrict out)
{
  for (int64_t a = 0; a < 2 * n; ++a)
    out[a] = v[a];
  for (int64_t r = 0; r < runs; ++r)
  {
    const int64_t a = row[r];
    const double v_a = v[2 * a], u_a = v[2 * a + 1];
    double sum0 = 0.0, sum1 = 0.0, t0 = 0.0, t1 = 0.0;
    int64_t k = begin[r];
    for (; k + 1 < begin[r + 1]; k += 2)
    {
      const int64_t b = j[k], c = j[k + 1];
      sum0 += w[k] * v[2 * b];
      t0 += w[k] * v[2 * b + 1];
      sum1 += w[k + 1] * v[2 * c];
      t1 += w[k + 1] * v[2 * c + 1];
      out[2 * b] += w[k] * v_a;
      out[2 * b + 1] += w[k] * u_a;
      out[2 * c] += w[k + 1] * v_a;
      out[2 * c + 1] += w[k + 1] * u_a;
    }
    if (k < begin[r + 1])
    {
      const int64_t b = j[k];
      sum0 += w[k] * v[2 * b];
      t0 += w[k] * v[2 * b + 1];
      out[2 * b] += w[k] * v_a;
      out[2 * b + 1] += w[k] * u_a;
    }
    out[2 * a] += sum0 + sum1;
    out[2 * a + 1] += t0 + t1;
  }
}

/* The pairs (i, j), i < j, of the n points x (n, gdim) at most `reach` apart, in runs of equal i
 * (ascending): (*runs, row, begin, j). Within a run the j come cube by cube, ascending within a
 * cube; rows of only later points keep the products' scatters ahead of their rows (10 % faster
 * than pairs found from either end).
 *
 * The points are sorted into cubes of side >= reach (num_cubes[c] along axis c from lo; the
 * cube of a point is clamped into the grid), so a pair lies in one cube or in two neighbouring
 * ones; in each of these cubes, point i meets the points after it (a binary search finds them).
 * Scratch: cube (n), order (n), start (number of cubes + 1).
 *
 * At most `capacity` pairs are written; counts[0] = runs and counts[1] = the number of pairs,
 * which exceeds `capacity` when the output was too short (call again with that much room). */
static inline void search(int32_t gdim, int64_t n, const double *restrict x, double reach,
                          const double *lo, double side, const int64_t *num_cubes, int64_t capacity,
                          int32_t *restrict row, int64_t *restrict begin, int32_t *restrict j,
                          int64_t *restrict cube, int32_t *restrict order, int64_t *restrict start,
                          int64_t *counts)
{
  int64_t total = 1;
  for (int32_t c = 0; c < gdim; ++c)
    total *= num_cubes[c];
  const double reach2 = reach * reach;
  /* the cube of each point (axis 0 fastest), and the points of each cube in ascending order */
  for (int64_t a = 0; a <= total; ++a)
    start[a] = 0;
  for (int64_t i = 0; i < n; ++i)
  {
    int64_t key = 0;
    for (int32_t c = gdim - 1; c >= 0; --c)
    {
      int64_t k = (int64_t)((x[i * gdim + c] - lo[c]) / side);
      k = k < 0 ? 0 : (k >= num_cubes[c] ? num_cubes[c] - 1 : k);
      key = key * num_cubes[c] + k;
    }
    cube[i] = key;
    ++start[key + 1];
  }
  for (int64_t a = 0; a < total; ++a)
    start[a + 1] += start[a];
  for (int64_t i = 0; i < n; ++i)
    order[start[cube[i]]++] = (int32_t)i;
  for (int64_t a = total; a > 0; --a) /* back to the first point of each cube */
    start[a] = start[a - 1];
  start[0] = 0;
  int64_t runs = 0, m = 0;
  for (int64_t i = 0; i < n; ++i)
  {
    const double *x_i = x + i * gdim;
    const int64_t first = m;
    int64_t at[3] = {0, 0, 0}, key = cube[i];
    for (int32_t c = 0; c < gdim; ++c)
    {
      at[c] = key % num_cubes[c];
      key /= num_cubes[c];
    }
    const int32_t d2_max = gdim == 3;
    for (int32_t d2 = -d2_max; d2 <= d2_max; ++d2)
      for (int32_t d1 = -1; d1 <= 1; ++d1)
        for (int32_t d0 = -1; d0 <= 1; ++d0)
        {
          const int64_t k0 = at[0] + d0, k1 = at[1] + d1, k2 = at[2] + d2;
          if (k0 < 0 || k0 >= num_cubes[0] || k1 < 0 || k1 >= num_cubes[1] || k2 < 0 ||
              (gdim == 3 && k2 >= num_cubes[2]))
            continue;
          const int64_t other = (k2 * num_cubes[1] + k1) * num_cubes[0] + k0;
          int64_t from = start[other], to = start[other + 1];
          while (from < to) /* the first point after i */
          {
            const int64_t mid = from + (to - from) / 2;
            if (order[mid] <= i)
              from = mid + 1;
            else
              to = mid;
          }
          for (int64_t p = from; p < start[other + 1]; ++p)
          {
            const int32_t b = order[p];
            const double *x_b = x + (int64_t)b * gdim;
            double d2 = 0.0;
            for (int32_t c = 0; c < gdim; ++c)
              d2 += (x_i[c] - x_b[c]) * (x_i[c] - x_b[c]);
            if (m < capacity)
              j[m] = b;
            m += d2 <= reach2;
          }
        }
    if (m > first)
    {
      if (m <= capacity)
      {
        row[runs] = (int32_t)i;
        begin[runs] = first;
      }
      ++runs;
    }
  }
  if (m <= capacity)
    begin[runs] = m;
  counts[0] = runs;
  counts[1] = m;
}

void pair_search(int64_t n, int32_t gdim, const double *x, double reach, const double *lo, double side,
                 const int64_t *num_cubes, int64_t capacity, int32_t *row, int64_t *begin, int32_t *j,
                 int64_t *cube, int32_t *order, int64_t *start, int64_t *counts)
{
  if (gdim == 2)
    search(2, n, x, reach, lo, side, num_cubes, capacity, row, begin, j, cube, order, start, counts);
  else
    search(3, n, x, reach, lo, side, num_cubes, capacity, row, begin, j, cube, order, start, counts);
}

/* Where each of the m ids `now` sits in the n ids `before`, when `now` is `before` with some
 * removed (the same order): at[k], or at[0] = -1 when it is not (then at is undefined). */
void subsequence(int64_t n, const int64_t *restrict before, int64_t m, const int64_t *restrict now,
                 int64_t *restrict at)
{
  int64_t i = 0;
  for (int64_t k = 0; k < m; ++k)
  {
    while (i < n && before[i] != now[k])
      ++i;
    if (i == n)
    {
      if (m > 0)
        at[0] = -1;
      return;
    }
    at[k] = i++;
  }
}

/* The largest squared distance of the n points x (n, gdim) from x_ref[slot[k]] (x_ref (*, gdim)),
 * over those with slot[k] >= 0; into *out. */
void max_moved2(int64_t n, int32_t gdim, const double *restrict x, const int64_t *restrict slot,
                const double *restrict x_ref, double *out)
{
  double largest = 0.0;
  for (int64_t k = 0; k < n; ++k)
  {
    if (slot[k] < 0)
      continue;
    double d2 = 0.0;
    for (int32_t c = 0; c < gdim; ++c)
    {
      const double u = x[k * gdim + c] - x_ref[slot[k] * gdim + c];
      d2 += u * u;
    }
    largest = d2 > largest ? d2 : largest;
  }
  *out = largest;
}
