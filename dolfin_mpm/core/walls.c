/* Loops of the rigid walls (walls.py), 2D: the walls of one line correct the velocities of the
 * nodes behind it, each in its share alpha of the node, in one pass over the nodes; and the
 * particles near some walls' lines are found in one pass over the particles. */
#include <math.h>
#include <stdint.h>

/* For each of the k nodes (indices into v, (num_nodes, 2)), each of the m walls of the line
 * (friction mu[w], velocity u_w[w] (m, 2)) takes the node's velocity v relative to it through
 * unilateral Coulomb contact (boundary.coulomb, with the wall's unit normal n into the wall):
 * change[w] = alpha[w] (coulomb(v - u_w) + u_w - v) (alpha (m, k), change (m, k, 2)); the node's
 * velocity becomes v + sum_w change[w]. */
void contact_apply(int64_t k, const int64_t *restrict nodes, const double *restrict n, int32_t m,
                   const double *restrict alpha, const double *restrict mu, const double *restrict u_w,
                   double *restrict v, double *restrict change)
{
  for (int64_t i = 0; i < k; ++i)
  {
    double *v_i = v + 2 * nodes[i];
    const double v0 = v_i[0], v1 = v_i[1];
    double total0 = 0.0, total1 = 0.0;
    for (int32_t w = 0; w < m; ++w)
    {
      double c0 = v0 - u_w[2 * w], c1 = v1 - u_w[2 * w + 1];
      const double vn = c0 * n[0] + c1 * n[1];
      if (vn > 0.0)
      {
        const double t0 = c0 - vn * n[0], t1 = c1 - vn * n[1];
        const double speed = sqrt(t0 * t0 + t1 * t1);
        const double scale = speed > 0.0 ? fmax(0.0, 1.0 - mu[w] * vn / speed) : 0.0;
        c0 = scale * t0;
        c1 = scale * t1;
      }
      const double a = alpha[w * k + i];
      double *d = change + 2 * (w * k + i);
      d[0] = a * (c0 + u_w[2 * w] - v0);
      d[1] = a * (c1 + u_w[2 * w + 1] - v1);
      total0 = w == 0 ? d[0] : total0 + d[0];
      total1 = w == 0 ? d[1] : total1 + d[1];
    }
    v_i[0] = v0 + total0;
    v_i[1] = v1 + total1;
  }
}

/* near[k] = whether point k of x (n, 3) lies less than limit[w] in front of the line of some of
 * the m walls (a_w - x) . n_w < limit[w], a_w (m, 2) a point of the line, n_w (m, 2) its normal. */
void near_lines(int64_t n, const double *restrict x, int32_t m, const double *restrict a,
                const double *restrict normal, const double *restrict limit, int8_t *restrict near)
{
  for (int64_t k = 0; k < n; ++k)
  {
    int8_t any = 0;
    for (int32_t w = 0; w < m; ++w)
      any |= (a[2 * w] - x[3 * k]) * normal[2 * w] + (a[2 * w + 1] - x[3 * k + 1]) * normal[2 * w + 1] < limit[w];
    near[k] = any;
  }
}
