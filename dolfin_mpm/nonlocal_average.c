/* Pair kernels of the non-local average (nonlocal_average.py): the weights and the product,
 * one pass over the pairs each, and the sort of a rebuild's pairs.
 *
 * A pair list is (i[k], j[k]), k < m, each unordered pair once, best in runs of equal i (the
 * rows); the weights are symmetric and the average applies A = I + W + W^T. Positions are
 * (n, gdim) row-major doubles, gdim 2 or 3.
 */
#include <math.h>
#include <stdint.h>

enum { CUBIC = 0, CONSTANT = 1, GAUSSIAN = 2 };

/* w(t) for t = min(s, 1): zero at t = 1, that is at and beyond the radius. */
static inline double weight(int32_t kind, double t)
{
  if (kind == CUBIC)
    return (1.0 - t) * (1.0 - t) * (1.0 + 2.0 * t); /* = 1 + t^2 (2t - 3), no cancellation */
  if (kind == CONSTANT)
    return t < 1.0 ? 1.0 : 0.0;
  return t < 1.0 ? exp(-2.5 * t * t) : 0.0;
}

static inline void weights_of(int32_t kind, int32_t gdim, int64_t m, const double *restrict x,
                              const int32_t *restrict i, const int32_t *restrict j, double inv_r,
                              double *restrict w)
{
  for (int64_t k = 0; k < m; ++k)
  {
    const double *x_a = x + (int64_t)i[k] * gdim, *x_b = x + (int64_t)j[k] * gdim;
    double d2 = 0.0;
    for (int32_t c = 0; c < gdim; ++c)
      d2 += (x_a[c] - x_b[c]) * (x_a[c] - x_b[c]);
    const double t = sqrt(d2) * inv_r;
    w[k] = weight(kind, t < 1.0 ? t : 1.0);
  }
}

/* w[k] = w(|x[i[k]] - x[j[k]]| / r). One loop per weight and dimension (2 or 3), each with
 * both inlined. (Accumulating A volume in the same loop made it slower than a second pass.) */
void pair_weights(int64_t m, int32_t gdim, const double *x, const int32_t *i, const int32_t *j,
                  double inv_r, int32_t kind, double *w)
{
#define WEIGHTS_OF(kind, gdim) weights_of(kind, gdim, m, x, i, j, inv_r, w)
  if (gdim == 2)
  {
    if (kind == CUBIC)
      WEIGHTS_OF(CUBIC, 2);
    else if (kind == CONSTANT)
      WEIGHTS_OF(CONSTANT, 2);
    else
      WEIGHTS_OF(GAUSSIAN, 2);
  }
  else
  {
    if (kind == CUBIC)
      WEIGHTS_OF(CUBIC, 3);
    else if (kind == CONSTANT)
      WEIGHTS_OF(CONSTANT, 3);
    else
      WEIGHTS_OF(GAUSSIAN, 3);
  }
#undef WEIGHTS_OF
}

/* out = A v = v + (W + W^T) v; v and out of length n. A row's own sum stays in two registers
 * (no chain of additions through memory); the other ends are scattered. */
void pair_apply(int64_t n, int64_t m, const int32_t *restrict i, const int32_t *restrict j,
                const double *restrict w, const double *restrict v, double *restrict out)
{
  for (int64_t a = 0; a < n; ++a)
    out[a] = v[a];
  int64_t k = 0;
  while (k < m)
  {
    const int32_t a = i[k];
    const double v_a = v[a];
    double sum0 = 0.0, sum1 = 0.0;
    for (; k + 1 < m && i[k + 1] == a; k += 2)
    {
      sum0 += w[k] * v[j[k]];
      sum1 += w[k + 1] * v[j[k + 1]];
      out[j[k]] += w[k] * v_a;
      out[j[k + 1]] += w[k + 1] * v_a;
    }
    if (k < m && i[k] == a)
    {
      sum0 += w[k] * v[j[k]];
      out[j[k]] += w[k] * v_a;
      ++k;
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
