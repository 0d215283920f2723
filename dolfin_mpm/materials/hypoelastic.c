/* The hypo-elastic predictor of elastic.py: one pass over the particles.
 *
 * Tensors are component-first: component (a, b) of the 3x3 stress of particle k at
 * [(3 a + b) n + k], of the gdim x gdim velocity gradient at [(gdim a + b) n + k]. The stress
 * is symmetric: only its upper triangle is read, and the result is exactly symmetric.
 */
#include <math.h>
#include <stdint.h>

#define AT(t, a, b) (t)[(3 * (a) + (b)) * n + k]
/* L_ab, zero outside the gdim x gdim block (plane strain). */
#define GRAD(a, b) ((a) < gdim && (b) < gdim ? L[(gdim * (a) + (b)) * n + k] : 0.0)

/* sigma_trial = Q sigma Q^T + dt (lambda tr(d) I + 2 G d), d = sym L and W = skew L, with the
 * Hughes–Winget rotation Q = (I - A)^-1 (I + A), A = dt W / 2, in closed form (Cayley):
 * Q = I + 2 (A + A^2) / (1 + |a|^2), a the axial vector of A. Returns it split into the
 * pressure p = -tr(sigma_trial) / 3 (n), the deviator s (3, 3, n) and q = sqrt(3/2 s:s) (n). */
static inline void trial_of(int32_t gdim, int64_t n, const double *restrict sigma, const double *restrict L,
                            double dt, double K, double G, double *restrict p, double *restrict s,
                            double *restrict q)
{
  const double lambda_dt = (K - 2.0 * G / 3.0) * dt, two_G_dt = 2.0 * G * dt;
  for (int64_t k = 0; k < n; ++k)
  {
    double d[3][3];
    for (int a = 0; a < 3; ++a)
      for (int b = a; b < 3; ++b)
        d[a][b] = 0.5 * (GRAD(a, b) + GRAD(b, a));
    const double a01 = 0.25 * dt * (GRAD(0, 1) - GRAD(1, 0)), a02 = 0.25 * dt * (GRAD(0, 2) - GRAD(2, 0)),
                 a12 = 0.25 * dt * (GRAD(1, 2) - GRAD(2, 1));
    const double scale = 2.0 / (1.0 + a01 * a01 + a02 * a02 + a12 * a12);
    double S[3][3], T[3][3];
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        S[a][b] = a <= b ? AT(sigma, a, b) : AT(sigma, b, a);
    if (a02 == 0.0 && a12 == 0.0)
    {
      /* A spin in the xy-plane (plane strain): Q rotates about z, [[c, t, 0], [-t, c, 0], [0, 0, 1]]. */
      const double c = 1.0 - scale * a01 * a01, t = scale * a01;
      const double QS[2][3] = {{c * S[0][0] + t * S[1][0], c * S[0][1] + t * S[1][1], c * S[0][2] + t * S[1][2]},
                               {c * S[1][0] - t * S[0][0], c * S[1][1] - t * S[0][1], c * S[1][2] - t * S[0][2]}};
      T[0][0] = QS[0][0] * c + QS[0][1] * t;
      T[0][1] = QS[0][1] * c - QS[0][0] * t;
      T[1][1] = QS[1][1] * c - QS[1][0] * t;
      T[0][2] = QS[0][2];
      T[1][2] = QS[1][2];
      T[2][2] = S[2][2];
    }
    else
    {
      const double A[3][3] = {{0.0, a01, a02}, {-a01, 0.0, a12}, {-a02, -a12, 0.0}};
      double Q[3][3], QS[3][3];
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
        {
          double A2 = 0.0;
          for (int c = 0; c < 3; ++c)
            A2 += A[a][c] * A[c][b];
          Q[a][b] = (a == b) + scale * (A[a][b] + A2);
        }
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
        {
          QS[a][b] = 0.0;
          for (int c = 0; c < 3; ++c)
            QS[a][b] += Q[a][c] * S[c][b];
        }
      for (int a = 0; a < 3; ++a)
        for (int b = a; b < 3; ++b)
        {
          T[a][b] = 0.0;
          for (int c = 0; c < 3; ++c)
            T[a][b] += QS[a][c] * Q[b][c];
        }
    }
    const double lambda_dt_tr = lambda_dt * (d[0][0] + d[1][1] + d[2][2]);
    for (int a = 0; a < 3; ++a)
      for (int b = a; b < 3; ++b)
        T[a][b] += two_G_dt * d[a][b] + (a == b) * lambda_dt_tr;
    const double p_k = -(T[0][0] + T[1][1] + T[2][2]) / 3.0;
    double ss = 0.0;
    for (int a = 0; a < 3; ++a)
      for (int b = a; b < 3; ++b)
      {
        const double s_ab = T[a][b] + (a == b) * p_k;
        AT(s, a, b) = AT(s, b, a) = s_ab;
        ss += (a == b ? 1.0 : 2.0) * s_ab * s_ab;
      }
    p[k] = p_k;
    q[k] = sqrt(1.5 * ss);
  }
}

/* The loop compiled for plane strain (gdim 2, a constant) and for any gdim. */
void hypoelastic_trial(int64_t n, int32_t gdim, const double *sigma, const double *L, double dt, double K,
                       double G, double *p, double *s, double *q)
{
  if (gdim == 2)
    trial_of(2, n, sigma, L, dt, K, G, p, s, q);
  else
    trial_of(gdim, n, sigma, L, dt, K, G, p, s, q);
}
