/* The volume-weighted mean stress of each particle's (cell, material) group, in place.
 * sigma is component-first (9, n); w[p] is the weight (0: the point is left as it is and out
 * of the means); total (size) and sums (9 * size) are zeroed scratch. */
#include <stdint.h>

void cell_mean(int64_t n, int64_t size, const int64_t *restrict key, const double *restrict w,
               double *restrict sigma, double *restrict total, double *restrict sums)
{
  for (int64_t p = 0; p < n; ++p)
  {
    const int64_t k = key[p];
    total[k] += w[p];
    for (int c = 0; c < 9; ++c)
      sums[9 * k + c] += w[p] * sigma[c * n + p];
  }
  for (int64_t k = 0; k < size; ++k)
    if (total[k] > 0.0)
      for (int c = 0; c < 9; ++c)
        sums[9 * k + c] /= total[k];
  for (int64_t p = 0; p < n; ++p)
    if (w[p] > 0.0)
    {
      const int64_t k = key[p];
      for (int c = 0; c < 9; ++c)
        sigma[c * n + p] = sums[9 * k + c];
    }
}
