/* The stress of a radial return (radial_return.py).
 *
 * Tensors are 3x3, component-first: component (a, b) of particle k at [(3 a + b) n + k]. The
 * particles go in blocks, one component at a time within a block: when n * 8 bytes is a
 * multiple of 4096 the components share their low address bits, and a loop over all of them
 * per particle stalls on false store-to-load dependencies (4K aliasing, 4x slower).
 */
#include <stdint.h>

enum { BLOCK = 512 };

/* sigma = (q / q_trial) s_trial - p I; no deviator where q_trial = 0. */
void radial_stress(int64_t n, const double *restrict s, const double *restrict q_trial,
                   const double *restrict q, const double *restrict p, double *restrict sigma)
{
  double scale[BLOCK];
  for (int64_t k0 = 0; k0 < n; k0 += BLOCK)
  {
    const int64_t m = n - k0 < BLOCK ? n - k0 : BLOCK;
    for (int64_t k = 0; k < m; ++k)
      scale[k] = q_trial[k0 + k] > 0.0 ? q[k0 + k] / q_trial[k0 + k] : 0.0;
    for (int64_t ab = 0; ab < 9; ++ab)
    {
      const double *restrict s_ab = s + ab * n + k0;
      double *restrict sigma_ab = sigma + ab * n + k0;
      if (ab % 4 == 0) /* diagonal */
        for (int64_t k = 0; k < m; ++k)
          sigma_ab[k] = s_ab[k] * scale[k] - p[k0 + k];
      else
        for (int64_t k = 0; k < m; ++k)
          sigma_ab[k] = s_ab[k] * scale[k];
    }
  }
}

/* The plastic work density of the return, sigma : C^-1 (sigma_trial - sigma) [J/m^3]:
 * w = p (p_trial - p) / K + s : (s_trial - s) / 2G with p = -tr(sigma) / 3, s = sigma + p I;
 * sigma and s_trial component-first (9, n). */
void plastic_work(int64_t n, const double *restrict sigma, const double *restrict p_trial,
                  const double *restrict s_trial, double K, double G, double *restrict w)
{
  for (int64_t k = 0; k < n; ++k)
  {
    const double p = -(sigma[k] + sigma[4 * n + k] + sigma[8 * n + k]) / 3.0;
    double sum = 0.0;
    for (int ab = 0; ab < 9; ++ab)
    {
      const double s = ab % 4 == 0 ? sigma[ab * n + k] + p : sigma[ab * n + k];
      sum += s * (s_trial[ab * n + k] - s);
    }
    w[k] = p * (p_trial[k] - p) / K + sum / (2.0 * G);
  }
}
