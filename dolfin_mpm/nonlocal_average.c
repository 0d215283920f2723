/* Pair kernels of the non-local average (nonlocal_average.py): the weights and the product,
 * one pass over the pairs each, and the sort of a rebuild's pairs.
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

enum { CUBIC = 0, CONSTANT = 1, GAUSSIAN = 2 };

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
  return exp(-2.5 * s2);
}

/* Two passes: the pairs closer than r from their squared distances, then the weights of the
 * kept ones (contiguous: no gathers, and no root for the pairs dropped). */
static inline int64_t weights_of(int32_t kind, int32_t gdim, int64_t runs, const int32_t *restrict row,
                                 const int64_t *restrict begin, const int32_t *restrict j,
                                 const double *restrict x, double inv_r, int32_t *restrict row_near,
                                 int64_t *restrict begin_near, int32_t *restrict j_near,
                                 double *restrict w)
{
  const double inv_r2 = inv_r * inv_r;
  int64_t runs_near = 0, count = 0;
  for (int64_t r = 0; r < runs; ++r)
  {
    const double *x_a = x + (int64_t)row[r] * gdim;
    const int64_t first = count;
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
  for (int64_t k = 0; k < count; ++k)
    w[k] = weight(kind, w[k]);
  return runs_near;
}

/* The pairs of the list (runs, row, begin, j) closer than r, in their order, to the list
 * (*runs_near, row_near, begin_near, j_near), with their weights w(|x_i - x_j| / r) in w.
 * One loop per weight and dimension (2 or 3), each with both inlined. (Accumulating A volume
 * in the same loop made it slower than a second pass.) */
void pair_weights(int64_t runs, const int32_t *row, const int64_t *begin, const int32_t *j,
                  int32_t gdim, const double *x, double inv_r, int32_t kind, int64_t *runs_near,
                  int32_t *row_near, int64_t *begin_near, int32_t *j_near, double *w)
{
#define WEIGHTS_OF(kind, gdim)                                                                      \
  weights_of(kind, gdim, runs, row, begin, j, x, inv_r, row_near, begin_near, j_near, w)
  if (gdim == 2)
    *runs_near = kind == CUBIC      ? WEIGHTS_OF(CUBIC, 2)
                 : kind == CONSTANT ? WEIGHTS_OF(CONSTANT, 2)
                                    : WEIGHTS_OF(GAUSSIAN, 2);
  else
    *runs_near = kind == CUBIC      ? WEIGHTS_OF(CUBIC, 3)
                 : kind == CONSTANT ? WEIGHTS_OF(CONSTANT, 3)
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

/* Stable counting sort of the pairs (key[k], other[k]) by key, into sorted_key and sorted_other. */
static void counting_sort(int64_t n, int64_t m, const int32_t *key, const int32_t *other,
                          int32_t *sorted_key, int32_t *sorted_other, int64_t *start)
{
  for (int64_t a = 0; a <= n; ++a)
    start[a] = 0;
  for (int64_t k = 0; k < m; ++k)
    ++start[key[k] + 1];
  for (int64_t a = 0; a < n; ++a)
    start[a + 1] += start[a];
  for (int64_t k = 0; k < m; ++k)
  {
    const int64_t to = start[key[k]]++;
    sorted_key[to] = key[k];
    sorted_other[to] = other[k];
  }
}

/* Sorts the pairs (i[k], j[k]) of particles 0..n-1 in place by i, then j: two counting sorts,
 * by j then (stably) by i, through the scratch arrays (m each, and n + 1 for start). */
void pair_sort(int64_t n, int64_t m, int32_t *i, int32_t *j, int32_t *scratch_i, int32_t *scratch_j,
               int64_t *start)
{
  counting_sort(n, m, j, i, scratch_j, scratch_i, start);
  counting_sort(n, m, scratch_i, scratch_j, i, j, start);
}
