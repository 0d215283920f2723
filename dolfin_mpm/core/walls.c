/* Loops of the rigid walls (walls.py), 2D and 3D: the walls of one line (plane) correct the
 * velocities of the nodes behind it, each in its share alpha of the node, in one pass over the
 * nodes; the particles near some walls' lines (planes) are found, and the masses of those over
 * each wall of a line are scattered to the nodes, in one pass over the particles each. Each
 * loop is compiled with the dimension a constant. */
#include <math.h>
#include <stdint.h>

#define INLINE static inline __attribute__((always_inline))

/* For each of the k nodes (indices into v, (num_nodes, gdim)), each of the m walls of the line
 * (friction mu[w], velocity u_w[w] (m, gdim)) takes the node's velocity v relative to it through
 * unilateral Coulomb contact (boundary.coulomb, with the wall's unit normal n into the wall):
 * change[w] = alpha[w] (coulomb(v - u_w) + u_w - v) (alpha (m, k), change (m, k, gdim)); the
 * node's velocity becomes v + sum_w change[w]. */
INLINE void contact_apply_of(int64_t k, int32_t gdim, const int64_t *restrict nodes, const double *restrict n,
                             int32_t m, const double *restrict alpha, const double *restrict mu,
                             const double *restrict u_w, double *restrict v, double *restrict change)
{
  for (int64_t i = 0; i < k; ++i)
  {
    double *v_i = v + gdim * nodes[i];
    double v0[3], total[3] = {0.0, 0.0, 0.0};
    for (int32_t c = 0; c < gdim; ++c)
      v0[c] = v_i[c];
    for (int32_t w = 0; w < m; ++w)
    {
      double rel[3], vn = 0.0;
      for (int32_t c = 0; c < gdim; ++c)
      {
        rel[c] = v0[c] - u_w[gdim * w + c];
        vn += rel[c] * n[c];
      }
      if (vn > 0.0)
      {
        double t[3], speed2 = 0.0;
        for (int32_t c = 0; c < gdim; ++c)
        {
          t[c] = rel[c] - vn * n[c];
          speed2 += t[c] * t[c];
        }
        const double speed = sqrt(speed2);
        const double scale = speed > 0.0 ? fmax(0.0, 1.0 - mu[w] * vn / speed) : 0.0;
        for (int32_t c = 0; c < gdim; ++c)
          rel[c] = scale * t[c];
      }
      const double a = alpha[w * k + i];
      double *d = change + gdim * (w * k + i);
      for (int32_t c = 0; c < gdim; ++c)
      {
        d[c] = a * (rel[c] + u_w[gdim * w + c] - v0[c]);
        total[c] = w == 0 ? d[c] : total[c] + d[c];
      }
    }
    for (int32_t c = 0; c < gdim; ++c)
      v_i[c] = v0[c] + total[c];
  }
}

void contact_apply(int64_t k, int32_t gdim, const int64_t *nodes, const double *n, int32_t m, const double *alpha,
                   const double *mu, const double *u_w, double *v, double *change)
{
  if (gdim == 2)
    contact_apply_of(k, 2, nodes, n, m, alpha, mu, u_w, v, change);
  else
    contact_apply_of(k, 3, nodes, n, m, alpha, mu, u_w, v, change);
}

/* near[k] = whether point k of x (n, 3) lies less than limit[w] in front of the line (plane) of
 * some of the m walls, (a_w - x) . n_w < limit[w], a_w (m, gdim) a point of it, n_w (m, gdim)
 * its normal. */
INLINE void near_lines_of(int64_t n, int32_t gdim, const double *restrict x, int32_t m, const double *restrict a,
                          const double *restrict normal, const double *restrict limit, int8_t *restrict near)
{
  for (int64_t k = 0; k < n; ++k)
  {
    int8_t any = 0;
    for (int32_t w = 0; w < m; ++w)
    {
      double d = 0.0;
      for (int32_t c = 0; c < gdim; ++c)
        d += (a[gdim * w + c] - x[3 * k + c]) * normal[gdim * w + c];
      any |= d < limit[w];
    }
    near[k] = any;
  }
}

void near_lines(int64_t n, int32_t gdim, const double *x, int32_t m, const double *a, const double *normal,
                const double *limit, int8_t *near)
{
  if (gdim == 2)
    near_lines_of(n, 2, x, m, a, normal, limit, near);
  else
    near_lines_of(n, 3, x, m, a, normal, limit, near);
}

/* For each of the m walls of a line: out[w, dofs[a, p]] += N[a, p] mass[p] over the particles p
 * (ascending) less than limit in front of the wall's line, d = (a_w - x) . n_w < limit, and over
 * the wall: in 2D 0 <= (x - a_w) . t_w <= length[w] (a_w its first point, t_w its tangent); in 3D
 * (x - shift_w) . inward[e] >= offset[e] for its edges e in [begin[w], begin[w + 1]) (shift_w:
 * its move since t = 0). x (n, 3); dofs, N (nn, n) as transfer.c; out (m, num_nodes) holds the
 * sums on entry. The terms and their order are those of transfer.c's scatter of each wall's
 * particles. */
INLINE void wall_shares_of(int64_t n, int32_t gdim, const double *restrict x, const double *restrict mass,
                           int32_t nn, const int32_t *restrict dofs, const double *restrict N,
                           int64_t num_nodes, int32_t m, const double *restrict a, const double *restrict normal,
                           double limit, const double *restrict tangent, const double *restrict length,
                           const double *restrict shift, const int32_t *restrict begin,
                           const double *restrict inward, const double *restrict offset, double *restrict out)
{
  for (int64_t p = 0; p < n; ++p)
  {
    const double *x_p = x + 3 * p;
    for (int32_t w = 0; w < m; ++w)
    {
      const double *a_w = a + gdim * w, *n_w = normal + gdim * w;
      double d = 0.0;
      for (int32_t c = 0; c < gdim; ++c)
        d += (a_w[c] - x_p[c]) * n_w[c];
      if (!(d < limit))
        continue;
      int over = 1;
      if (gdim == 2)
      {
        const double s = (x_p[0] - a_w[0]) * tangent[2 * w] + (x_p[1] - a_w[1]) * tangent[2 * w + 1];
        over = s >= 0.0 && s <= length[w];
      }
      else
      {
        const double y[3] = {x_p[0] - shift[3 * w], x_p[1] - shift[3 * w + 1], x_p[2] - shift[3 * w + 2]};
        for (int32_t e = begin[w]; e < begin[w + 1] && over; ++e)
          over = y[0] * inward[3 * e] + y[1] * inward[3 * e + 1] + y[2] * inward[3 * e + 2] >= offset[e];
      }
      if (!over)
        continue;
      double *o = out + w * num_nodes;
      for (int32_t k = 0; k < nn; ++k)
        o[dofs[k * n + p]] += N[k * n + p] * mass[p];
    }
  }
}

void wall_shares(int64_t n, int32_t gdim, const double *x, const double *mass, const int32_t *dofs, const double *N,
                 int64_t num_nodes, int32_t m, const double *a, const double *normal, double limit,
                 const double *tangent, const double *length, const double *shift, const int32_t *begin,
                 const double *inward, const double *offset, double *out)
{
  if (gdim == 2)
    wall_shares_of(n, 2, x, mass, 3, dofs, N, num_nodes, m, a, normal, limit, tangent, length, shift, begin, inward,
                   offset, out);
  else
    wall_shares_of(n, 3, x, mass, 4, dofs, N, num_nodes, m, a, normal, limit, tangent, length, shift, begin, inward,
                   offset, out);
}
