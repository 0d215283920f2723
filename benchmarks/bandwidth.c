/* STREAM's copy and triad on one core, for silo_step.py to set its times against: each loop
 * moves 16 (copy) or 24 (triad) bytes per element, counted as STREAM counts them. */
#include <stdint.h>

void stream_copy(int64_t n, const double *restrict a, double *restrict b)
{
  for (int64_t i = 0; i < n; ++i)
    b[i] = a[i];
}

void stream_triad(int64_t n, const double *restrict b, const double *restrict c, double s, double *restrict a)
{
  for (int64_t i = 0; i < n; ++i)
    a[i] = b[i] + s * c[i];
}
