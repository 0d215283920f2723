/* The viscoplastic return of drucker_prager.py: one pass over the particles. */
#include <math.h>
#include <stdint.h>

/* Root x in [0, x_tr] of x + a x^N = x_tr: Newton's method, safeguarded by bisection. */
static double overstress(double x_tr, double a, double N)
{
  double lo = 0.0, hi = x_tr, x = fmin(x_tr, pow(x_tr / a, 1.0 / N)); /* the root when a x^N dominates */
  for (int it = 0; it < 100; ++it)
  {
    const double h = x + a * pow(x, N) - x_tr;
    if (h < 0.0)
      lo = x;
    if (h > 0.0)
      hi = x;
    double x_new = x - h / (1.0 + a * N * pow(x, N - 1.0));
    if (!(x_new > lo && x_new < hi))
      x_new = 0.5 * (lo + hi);
    if (fabs(x_new - x) <= 1e-13 * fmax(x_tr, 1e-300))
      return x_new;
    x = x_new;
  }
  return x;
}

/* Equivalent viscoplastic strain increment de (n) of backward Euler from the trial pressure p
 * and equivalent stress q (n): with y = m (p + c cot phi) and the relative overstress
 * x = q / y - 1 of the end state, x + a x^N = x_tr, a = 3 G gamma dt / y, de = (x_tr - x) y / 2G.
 * At the apex (y <= 0) de = q / 2G; below the cone de = 0. three_G_gamma_dt = inf is the
 * rate-independent limit (x = 0). */
void dp_increment(int64_t n, const double *restrict p, const double *restrict q, double m,
                  double tension_limit, double G, double three_G_gamma_dt, double N, double *restrict de)
{
  for (int64_t k = 0; k < n; ++k)
  {
    const double y = m * (p[k] + tension_limit);
    if (y <= 0.0)
      de[k] = q[k] / (2.0 * G);
    else if (q[k] > y)
    {
      const double x_tr = (q[k] - y) / y, a = three_G_gamma_dt / y;
      const double x = isinf(a) ? 0.0 : N == 1.0 ? x_tr / (1.0 + a) : overstress(x_tr, a, N);
      de[k] = (x_tr - x) * y / (2.0 * G);
    }
    else
      de[k] = 0.0;
  }
}

/* End-state pressure p and equivalent stress q (n) of the trial state (p_trial, q_trial) and the
 * increments de, or de_nonlocal where larger: q = max(q_trial - 2 G max(de, de_nonlocal), 0);
 * at the apex (p_trial <= -c cot phi) q = 0 and p = -c cot phi. */
void dp_end_state(int64_t n, const double *restrict p_trial, const double *restrict q_trial,
                  const double *restrict de, const double *restrict de_nonlocal, double G,
                  double tension_limit, double *restrict p, double *restrict q)
{
  const double two_G = 2.0 * G;
  for (int64_t k = 0; k < n; ++k)
  {
    const double d = de_nonlocal[k] > de[k] ? de_nonlocal[k] : de[k];
    const double q_k = q_trial[k] - two_G * d;
    const int apex = p_trial[k] <= -tension_limit;
    q[k] = apex || !(q_k > 0.0) ? 0.0 : q_k;
    p[k] = apex ? -tension_limit : p_trial[k];
  }
}
