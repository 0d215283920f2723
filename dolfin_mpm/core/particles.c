/* The particles' move at the end of a step (particles.py), with the test that the step left
 * them sound, in one pass over the arrays it reads.
 *
 * x (n, 3) row-major takes x[p, c] += dx[p, c] for c < gdim (dx (n, gdim)); *bad is set to 1
 * if any value among x, v (n gdim values) and sigma (9 n values, in any layout) is not finite
 * or any volume is not > 0, else 0. A value is not finite when its exponent bits are all set:
 * an integer test whose OR over the values vectorises (the floating-point ones in a reduction
 * would not, without reassociation). */
#include <stdint.h>
#include <string.h>

static uint64_t not_finite(int64_t m, const double *restrict a)
{
  const uint64_t exponent = 0x7ff0000000000000u;
  uint64_t any = 0;
  for (int64_t k = 0; k < m; ++k)
  {
    uint64_t u;
    memcpy(&u, a + k, sizeof u);
    any |= (u & exponent) == exponent;
  }
  return any;
}

void move(int64_t n, int32_t gdim, double *restrict x, const double *restrict dx, const double *restrict v,
          const double *restrict sigma, const double *restrict volume, int64_t *bad)
{
  if (gdim == 2)
    for (int64_t p = 0; p < n; ++p)
    {
      x[3 * p] += dx[2 * p];
      x[3 * p + 1] += dx[2 * p + 1];
    }
  else
    for (int64_t p = 0; p < n; ++p)
      for (int32_t c = 0; c < gdim; ++c)
        x[3 * p + c] += dx[gdim * p + c];
  uint64_t any = not_finite(3 * n, x) | not_finite(gdim * n, v) | not_finite(9 * n, sigma);
  for (int64_t p = 0; p < n; ++p)
    any |= !(volume[p] > 0.0);
  *bad = (int64_t)any;
}
