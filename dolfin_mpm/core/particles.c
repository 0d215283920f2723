/* The check of particles.py: one pass over an array, no sums that could overflow. */
#include <stdint.h>

/* *bad = whether any of the n doubles of a is NaN or infinite (a - a is then NaN, not 0). */
void any_not_finite(int64_t n, const double *restrict a, int32_t *bad)
{
  int32_t found = 0;
  for (int64_t i = 0; i < n; ++i)
    found |= !(a[i] - a[i] == 0.0);
  *bad = found;
}
