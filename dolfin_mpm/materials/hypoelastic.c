/* The hypo-elastic predictor of elastic.py: one pass over the particles.
 *
 * Tensors are component-first: component (a, b) of the 3x3 stress of particle k at
 * [(3 a + b) n + k], of the gdim x gdim velocity gradient (gdim 2 or 3) at [(gdim a + b) n + k].
 * The stress is symmetric: only its upper triangle is read, and the result is exactly symmetric.
 */
#include <math.h>
#include <stdint.h>

#define AT(t, a, b) (t)[(3 * (a) + (b)) * n + k]
/* The components of one array do not overlap: GCC cannot prove it (they are apart by n, unknown
 * at compile time) and without this leaves the loops unvectorised, 1.7x slower in SSE2 and 3x
 * in AVX2. */
#define IVDEP _Pragma("GCC ivdep")

/* 3D (L of 3 x 3): sigma_trial = Q sigma Q^T + dt (lambda tr(d) I + 2 G d), d = sym L and
 * W = skew L, with the
 * Hughes–Winget rotation Q = (I - A)^-1 (I + A), A = dt W / 2, in closed form (Cayley):
 * Q = I + 2 (A + A^2) / (1 + |a|^2), a the axial vector of A. Returns it split into the
 * pressure p = -tr(sigma_trial) / 3 (n), the deviator s (3, 3, n) and q = sqrt(3/2 s:s) (n). */
static void space_trial(int64_t n, const double *restrict sigma, const double *restrict L,
                        double dt, double K, double G, double *restrict p, double *restrict s,
                        double *restrict q)
{
  const double lambda_dt = (K - 2.0 * G / 3.0) * dt, two_G_dt = 2.0 * G * dt;
  IVDEP
  for (int64_t k = 0; k < n; ++k)
  {
    double d[3][3];
    for (int a = 0; a < 3; ++a)
      for (int b = a; b < 3; ++b)
        d[a][b] = 0.5 * (AT(L, a, b) + AT(L, b, a));
    const double a01 = 0.25 * dt * (AT(L, 0, 1) - AT(L, 1, 0)), a02 = 0.25 * dt * (AT(L, 0, 2) - AT(L, 2, 0)),
                 a12 = 0.25 * dt * (AT(L, 1, 2) - AT(L, 2, 1));
    const double scale = 2.0 / (1.0 + a01 * a01 + a02 * a02 + a12 * a12);
    double S[3][3], T[3][3];
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        S[a][b] = a <= b ? AT(sigma, a, b) : AT(sigma, b, a);
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

/* The same for plane strain (gdim 2, L of 2 x 2), written out: the rotation is about z, and
 * straight-line code runs twice as fast as the loops over the components above. */
static void plane_strain_trial(int64_t n, const double *restrict sigma, const double *restrict L, double dt,
                               double K, double G, double *restrict p, double *restrict s,
                               double *restrict q)
{
  const double lambda_dt = (K - 2.0 * G / 3.0) * dt, two_G_dt = 2.0 * G * dt;
  const double *S00 = sigma, *S01 = sigma + n, *S02 = sigma + 2 * n, *S11 = sigma + 4 * n,
               *S12 = sigma + 5 * n, *S22 = sigma + 8 * n;
  const double *L00 = L, *L01 = L + n, *L10 = L + 2 * n, *L11 = L + 3 * n;
  IVDEP
  for (int64_t k = 0; k < n; ++k)
  {
    const double d01 = 0.5 * (L01[k] + L10[k]), a01 = 0.25 * dt * (L01[k] - L10[k]);
    const double scale = 2.0 / (1.0 + a01 * a01);
    const double c = 1.0 - scale * a01 * a01, t = scale * a01;
    const double QS00 = c * S00[k] + t * S01[k], QS01 = c * S01[k] + t * S11[k];
    const double QS10 = c * S01[k] - t * S00[k], QS11 = c * S11[k] - t * S01[k];
    const double lambda_dt_tr = lambda_dt * (L00[k] + L11[k]);
    const double T00 = QS00 * c + QS01 * t + (two_G_dt * L00[k] + lambda_dt_tr);
    const double T01 = QS01 * c - QS00 * t + two_G_dt * d01;
    const double T11 = QS11 * c - QS10 * t + (two_G_dt * L11[k] + lambda_dt_tr);
    const double T02 = c * S02[k] + t * S12[k], T12 = c * S12[k] - t * S02[k];
    const double T22 = S22[k] + lambda_dt_tr;
    const double p_k = -(T00 + T11 + T22) / 3.0;
    const double s00 = T00 + p_k, s11 = T11 + p_k, s22 = T22 + p_k;
    AT(s, 0, 0) = s00;
    AT(s, 1, 1) = s11;
    AT(s, 2, 2) = s22;
    AT(s, 0, 1) = AT(s, 1, 0) = T01;
    AT(s, 0, 2) = AT(s, 2, 0) = T02;
    AT(s, 1, 2) = AT(s, 2, 1) = T12;
    p[k] = p_k;
    q[k] = sqrt(1.5 * (s00 * s00 + 2.0 * T01 * T01 + 2.0 * T02 * T02 + s11 * s11 + 2.0 * T12 * T12 + s22 * s22));
  }
}

void hypoelastic_trial(int64_t n, int32_t gdim, const double *sigma, const double *L, double dt, double K,
                       double G, double *p, double *s, double *q)
{
  if (gdim == 2)
    plane_strain_trial(n, sigma, L, dt, K, G, p, s, q);
  else
    space_trial(n, sigma, L, dt, K, G, p, s, q);
}
