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

/* Particles stopped on rigid walls, one pass over the points, each point's walls in order
 * (walls.py's stop_at_walls). Point k of x (n, 3) moving by dx (n, gdim) with velocity v (n, gdim)
 * reaches wall w when it lies less than limit[w] in front of its line (plane),
 * phi0 = (a_w - x) . n_w < limit[w], crosses it, phi1 = phi0 - dx . n_w + advance[w] < 0 with
 * phi0 >= -roundoff[w] (those stopped before too), at a point over the wall as it is then (share
 * phi0 / (phi0 - phi1) of the step): in 2D 0 <= (crossing - a_w) . t_w - shift_t[w] share <=
 * length[w]; in 3D (crossing - shift_w - dt share u_w) . inward[e] >= offset[e] for its edges e in
 * [begin[w], begin[w + 1]). Then dx += (phi1 - roundoff[w]) n_w puts it a round-off in front of
 * the wall and v loses its component into the wall, relative to the wall's velocity u_w (m, gdim).
 * stopped[0] counts the stops. */
INLINE void stop_of(int64_t n, int32_t gdim, const double *restrict x, double *restrict dx, double *restrict v,
                    int32_t m, const double *restrict a, const double *restrict normal,
                    const double *restrict limit, const double *restrict advance, const double *restrict roundoff,
                    const double *restrict tangent, const double *restrict length, const double *restrict shift_t,
                    const double *restrict u, const double *restrict shift, double dt, const int32_t *restrict begin,
                    const double *restrict inward, const double *restrict offset, int64_t *restrict stopped)
{
  int64_t count = 0;
  for (int64_t k = 0; k < n; ++k)
  {
    const double *x_k = x + 3 * k;
    double *dx_k = dx + gdim * k, *v_k = v + gdim * k;
    for (int32_t w = 0; w < m; ++w)
    {
      const double *a_w = a + gdim * w, *n_w = normal + gdim * w, *u_w = u + gdim * w;
      double phi0 = 0.0;
      for (int32_t c = 0; c < gdim; ++c)
        phi0 += (a_w[c] - x_k[c]) * n_w[c];
      if (!(phi0 < limit[w]))
        continue;
      double phi1 = phi0 - dx_k[0] * n_w[0] - dx_k[1] * n_w[1] + advance[w];
      if (gdim == 3)
        phi1 -= dx_k[2] * n_w[2];
      if (!(phi1 < 0.0 && phi0 >= -roundoff[w]))
        continue;
      const double share = phi0 / (phi0 - phi1);
      double crossing[3];
      for (int32_t c = 0; c < gdim; ++c)
        crossing[c] = x_k[c] + share * dx_k[c];
      int on = 1;
      if (gdim == 2)
      {
        const double along = (crossing[0] - a_w[0]) * tangent[2 * w] + (crossing[1] - a_w[1]) * tangent[2 * w + 1] -
                             shift_t[w] * share;
        on = along >= 0.0 && along <= length[w];
      }
      else
      {
        double y[3];
        for (int32_t c = 0; c < 3; ++c)
          y[c] = crossing[c] - shift[3 * w + c] - dt * share * u_w[c];
        for (int32_t e = begin[w]; e < begin[w + 1] && on; ++e)
          on = y[0] * inward[3 * e] + y[1] * inward[3 * e + 1] + y[2] * inward[3 * e + 2] >= offset[e];
      }
      if (!on)
        continue;
      for (int32_t c = 0; c < gdim; ++c)
        dx_k[c] += (phi1 - roundoff[w]) * n_w[c];
      double vn = 0.0;
      for (int32_t c = 0; c < gdim; ++c)
        vn += (v_k[c] - u_w[c]) * n_w[c];
      const double into = vn > 0.0 || vn != vn ? vn : 0.0; /* max(vn, 0), NaN kept */
      for (int32_t c = 0; c < gdim; ++c)
        v_k[c] -= into * n_w[c];
      ++count;
    }
  }
  stopped[0] = count;
}

void stop_at_walls(int64_t n, int32_t gdim, const double *x, double *dx, double *v, int32_t m, const double *a,
                   const double *normal, const double *limit, const double *advance, const double *roundoff,
                   const double *tangent, const double *length, const double *shift_t, const double *u,
                   const double *shift, double dt, const int32_t *begin, const double *inward, const double *offset,
                   int64_t *stopped)
{
  if (gdim == 2)
    stop_of(n, 2, x, dx, v, m, a, normal, limit, advance, roundoff, tangent, length, shift_t, u, shift, dt, begin,
            inward, offset, stopped);
  else
    stop_of(n, 3, x, dx, v, m, a, normal, limit, advance, roundoff, tangent, length, shift_t, u, shift, dt, begin,
            inward, offset, stopped);
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
