/* Particle-to-grid and grid-to-particle loops of transfer.py, one pass over the particles each.
 *
 * Particle p lies in cell cells[p] with the nn = gdim + 1 nodes dofs[a n + p] (int32) and basis
 * values N[a n + p] (component-first, as locate.Basis); the cell's basis gradients are
 * grad[(cells[p] nn + a) gdim + j] (cell-first, the grid's table). Nodal
 * arrays are (num_nodes, k) and particle arrays (n, k), row-major. Sums run over the cell's
 * nodes in order; a nodal sum takes its particles' terms in the particles' order (one pass over
 * the particles, each of its nodes in turn). Each loop is compiled for 2D and 3D with the
 * dimension a constant (fully unrolled inner loops) and once for any other.
 */
#include <stdint.h>

#define INLINE static inline __attribute__((always_inline))

/* Whether particle p lies in the cell of nodes d[0..nn): particles of one cell come in runs
 * where they are ordered by cell, and a run's nodal sums are held in registers, starting from
 * the stored sums: the terms and their order are those of one particle at a time, without a
 * store and reload of the same node between consecutive particles. */
INLINE int same_cell(int64_t n, int32_t nn, const int32_t *restrict dofs, int64_t p, const int64_t *d)
{
  for (int32_t a = 0; a < nn; ++a)
    if (dofs[a * n + p] != d[a])
      return 0;
  return 1;
}

INLINE void cell_of(int64_t n, int32_t nn, const int32_t *restrict dofs, int64_t p, int64_t *d)
{
  for (int32_t a = 0; a < nn; ++a)
    d[a] = dofs[a * n + p];
}

/* Component i of particle p's internal force at its node a: sum_j sigma_ij V dN_aj, with dN the
 * gradients of p's cell, (nn, gdim). */
INLINE double force_term(int64_t n, int32_t gdim, const double *restrict sigma, const double *restrict volume,
                         const double *restrict dN, int64_t p, int32_t a, int32_t i)
{
  double f = 0.0;
  for (int32_t j = 0; j < gdim; ++j)
    f += sigma[(3 * i + j) * n + p] * volume[p] * dN[a * gdim + j];
  return f;
}

/* The basis gradients (nn, gdim) of particle p's cell. */
INLINE const double *grad_of(int32_t gdim, const int32_t *restrict cells, const double *restrict grad, int64_t p)
{
  return grad + (int64_t)cells[p] * (gdim + 1) * gdim;
}

#define MAX_NODES 4 /* a tetrahedron */
#define MAX_K 9

/* out[dofs[a, p], c] += N[a, p] values[p, c]; out (num_nodes, k) holds the sums on entry. */
INLINE void scatter_of(int64_t n, int32_t nn, const int32_t *restrict dofs, const double *restrict N, int32_t k,
                       const double *restrict values, double *restrict out)
{
  if (nn > MAX_NODES || k > MAX_K)
  {
    for (int64_t p = 0; p < n; ++p)
      for (int32_t a = 0; a < nn; ++a)
        for (int32_t c = 0; c < k; ++c)
          out[(int64_t)dofs[a * n + p] * k + c] += N[a * n + p] * values[p * k + c];
    return;
  }
  int64_t p = 0, d[MAX_NODES];
  double o[MAX_NODES][MAX_K];
  while (p < n)
  {
    cell_of(n, nn, dofs, p, d);
    for (int32_t a = 0; a < nn; ++a)
      for (int32_t c = 0; c < k; ++c)
        o[a][c] = out[d[a] * k + c];
    for (; p < n && same_cell(n, nn, dofs, p, d); ++p)
      for (int32_t a = 0; a < nn; ++a)
        for (int32_t c = 0; c < k; ++c)
          o[a][c] += N[a * n + p] * values[p * k + c];
    for (int32_t a = 0; a < nn; ++a)
      for (int32_t c = 0; c < k; ++c)
        out[d[a] * k + c] = o[a][c];
  }
}

/* out[dofs[a, p], i] += sum_j (sigma_ij[p] volume[p]) dN_aj[p]: the internal forces R of the
 * stresses sigma, component-first (3, 3, n); out (num_nodes, gdim) holds the sums on entry;
 * gdim 2 or 3. */
INLINE void internal_force_of(int64_t n, int32_t gdim, const int32_t *restrict dofs,
                              const int32_t *restrict cells, const double *restrict grad,
                              const double *restrict sigma, const double *restrict volume,
                              double *restrict out)
{
  const int32_t nn = gdim + 1;
  int64_t p = 0, d[MAX_NODES];
  double o[MAX_NODES][3];
  while (p < n)
  {
    const int32_t cell = cells[p];
    const double *dN = grad_of(gdim, cells, grad, p);
    cell_of(n, nn, dofs, p, d);
    for (int32_t a = 0; a < nn; ++a)
      for (int32_t i = 0; i < gdim; ++i)
        o[a][i] = out[d[a] * gdim + i];
    for (; p < n && cells[p] == cell; ++p)
      for (int32_t a = 0; a < nn; ++a)
        for (int32_t i = 0; i < gdim; ++i)
          o[a][i] += force_term(n, gdim, sigma, volume, dN, p, a, i);
    for (int32_t a = 0; a < nn; ++a)
      for (int32_t i = 0; i < gdim; ++i)
        out[d[a] * gdim + i] = o[a][i];
  }
}

/* out[p, c] = sum_a N[a, p] nodal[dofs[a, p], c], out (n, k). */
INLINE void interpolate_of(int64_t n, int32_t nn, const int32_t *restrict dofs, const double *restrict N,
                           int32_t k, const double *restrict nodal, double *restrict out)
{
  for (int64_t p = 0; p < n; ++p)
    for (int32_t c = 0; c < k; ++c)
    {
      double sum = 0.0;
      for (int32_t a = 0; a < nn; ++a)
        sum += N[a * n + p] * nodal[(int64_t)dofs[a * n + p] * k + c];
      out[p * k + c] = sum;
    }
}

/* out[i, j, p] = sum_a nodal[dofs[a, p], i] dN[a, j]: the gradient of a nodal field with k
 * components, component-first (k, gdim, n). It is constant in a cell: computed once for each run
 * of particles in one cell and written to each of them. */
INLINE void gradient_of(int64_t n, int32_t gdim, const int32_t *restrict dofs, const int32_t *restrict cells,
                        const double *restrict grad, int32_t k, const double *restrict nodal,
                        double *restrict out)
{
  const int32_t nn = gdim + 1;
  double G[MAX_K][3];
  for (int64_t p = 0; p < n; ++p)
  {
    if (p == 0 || cells[p] != cells[p - 1])
    {
      const double *dN = grad_of(gdim, cells, grad, p);
      for (int32_t i = 0; i < k; ++i)
        for (int32_t j = 0; j < gdim; ++j)
        {
          double sum = 0.0;
          for (int32_t a = 0; a < nn; ++a)
            sum += nodal[(int64_t)dofs[a * n + p] * k + i] * dN[a * gdim + j];
          G[i][j] = sum;
        }
    }
    for (int32_t i = 0; i < k; ++i)
      for (int32_t j = 0; j < gdim; ++j)
        out[(i * gdim + j) * n + p] = G[i][j];
  }
}

/* dx[p] = dt sum_a N[a, p] v_node[dofs[a, p]], the particle's displacement with the grid's
 * velocity, and the new particle velocity v[p]: v_p + dt sum_a N a_node (flip = 1),
 * flip (v_p + dt sum_a N a_node) + (1 - flip) sum_a N v_node (0 < flip < 1) or sum_a N v_node
 * (flip = 0); all (n, gdim) or (num_nodes, gdim). With musl, also the nodal sums of the momenta
 * m_p v[p] into momenta (num_nodes, gdim), which holds the sums on entry. One pass: a run of
 * particles of one cell reads its nodes' values and sums its momenta in registers. The terms
 * and their order are those of interpolate and scatter. */
INLINE void g2p_of(int64_t n, int32_t gdim, const int32_t *restrict dofs, const double *restrict N,
                   const double *restrict v_node, const double *restrict a_node, const double *restrict v_p,
                   double dt, double flip, int32_t musl, const double *restrict mass, double *restrict v,
                   double *restrict dx, double *restrict momenta)
{
  const int32_t nn = gdim + 1;
  int64_t p = 0, d[MAX_NODES];
  double vn[MAX_NODES][3], an[MAX_NODES][3], o[MAX_NODES][3];
  while (p < n)
  {
    cell_of(n, nn, dofs, p, d);
    for (int32_t a = 0; a < nn; ++a)
      for (int32_t c = 0; c < gdim; ++c)
      {
        vn[a][c] = v_node[d[a] * gdim + c];
        an[a][c] = flip > 0.0 ? a_node[d[a] * gdim + c] : 0.0;
        o[a][c] = musl ? momenta[d[a] * gdim + c] : 0.0;
      }
    for (; p < n && same_cell(n, nn, dofs, p, d); ++p)
      for (int32_t c = 0; c < gdim; ++c)
      {
        double vi = 0.0, ai = 0.0, vc;
        for (int32_t a = 0; a < nn; ++a)
          vi += N[a * n + p] * vn[a][c];
        dx[p * gdim + c] = dt * vi;
        if (flip > 0.0)
          for (int32_t a = 0; a < nn; ++a)
            ai += N[a * n + p] * an[a][c];
        if (flip == 1.0)
          vc = v_p[p * gdim + c] + dt * ai;
        else if (flip > 0.0)
          vc = flip * (v_p[p * gdim + c] + dt * ai) + (1.0 - flip) * vi;
        else
          vc = vi;
        v[p * gdim + c] = vc;
        if (musl)
          for (int32_t a = 0; a < nn; ++a)
            o[a][c] += N[a * n + p] * (mass[p] * vc);
      }
    if (musl)
      for (int32_t a = 0; a < nn; ++a)
        for (int32_t c = 0; c < gdim; ++c)
          momenta[d[a] * gdim + c] = o[a][c];
  }
}

/* P2G in one pass over the particles: the nodal sums of the masses m_p, the momenta m_p v_p and
 * the internal forces of the stresses sigma (component-first (3, 3, n)) and volumes, into mass
 * (num_nodes), momentum and force (num_nodes, gdim), each holding the sums on entry; the terms
 * and their order are those of scatter and internal_force. */
INLINE void p2g_of(int64_t n, int32_t gdim, const int32_t *restrict dofs, const double *restrict N,
                   const int32_t *restrict cells, const double *restrict grad, const double *restrict m,
                   const double *restrict v_p,
                   const double *restrict sigma, const double *restrict volume, double *restrict mass,
                   double *restrict momentum, double *restrict force)
{
  const int32_t nn = gdim + 1;
  int64_t p = 0, d[MAX_NODES];
  double ms[MAX_NODES], mv[MAX_NODES][3], fs[MAX_NODES][3];
  while (p < n)
  {
    const int32_t cell = cells[p];
    const double *dN = grad_of(gdim, cells, grad, p);
    cell_of(n, nn, dofs, p, d);
    for (int32_t a = 0; a < nn; ++a)
    {
      ms[a] = mass[d[a]];
      for (int32_t c = 0; c < gdim; ++c)
      {
        mv[a][c] = momentum[d[a] * gdim + c];
        fs[a][c] = force[d[a] * gdim + c];
      }
    }
    for (; p < n && cells[p] == cell; ++p)
      for (int32_t a = 0; a < nn; ++a)
      {
        const double N_ap = N[a * n + p];
        ms[a] += N_ap * m[p];
        for (int32_t c = 0; c < gdim; ++c)
          mv[a][c] += N_ap * (m[p] * v_p[p * gdim + c]);
        for (int32_t i = 0; i < gdim; ++i)
          fs[a][i] += force_term(n, gdim, sigma, volume, dN, p, a, i);
      }
    for (int32_t a = 0; a < nn; ++a)
    {
      mass[d[a]] = ms[a];
      for (int32_t c = 0; c < gdim; ++c)
      {
        momentum[d[a] * gdim + c] = mv[a][c];
        force[d[a] * gdim + c] = fs[a][c];
      }
    }
  }
}

/* The exported loops, with the common sizes as constants: 2D (3 nodes) and 3D (4 nodes), k = 1
 * or gdim components. */
void scatter(int64_t n, int32_t nn, const int32_t *dofs, const double *N, int32_t k, const double *values,
             double *out)
{
  if (nn == 3 && k <= 2)
    k == 1 ? scatter_of(n, 3, dofs, N, 1, values, out) : scatter_of(n, 3, dofs, N, 2, values, out);
  else if (nn == 4 && (k == 1 || k == 3))
    k == 1 ? scatter_of(n, 4, dofs, N, 1, values, out) : scatter_of(n, 4, dofs, N, 3, values, out);
  else
    scatter_of(n, nn, dofs, N, k, values, out);
}

void internal_force(int64_t n, int32_t gdim, const int32_t *dofs, const int32_t *cells, const double *grad,
                    const double *sigma, const double *volume, double *out)
{
  if (gdim == 2)
    internal_force_of(n, 2, dofs, cells, grad, sigma, volume, out);
  else
    internal_force_of(n, 3, dofs, cells, grad, sigma, volume, out);
}

void interpolate(int64_t n, int32_t nn, const int32_t *dofs, const double *N, int32_t k, const double *nodal,
                 double *out)
{
  if (nn == k + 1 && (k == 2 || k == 3)) /* vectors of the mesh's dimension */
    k == 2 ? interpolate_of(n, 3, dofs, N, 2, nodal, out) : interpolate_of(n, 4, dofs, N, 3, nodal, out);
  else
    interpolate_of(n, nn, dofs, N, k, nodal, out);
}

void gradient(int64_t n, int32_t gdim, const int32_t *dofs, const int32_t *cells, const double *grad, int32_t k,
              const double *nodal, double *out)
{
  if (k == gdim && (k == 2 || k == 3)) /* the velocity gradient */
    k == 2 ? gradient_of(n, 2, dofs, cells, grad, 2, nodal, out)
           : gradient_of(n, 3, dofs, cells, grad, 3, nodal, out);
  else
    gradient_of(n, gdim, dofs, cells, grad, k, nodal, out);
}


/* The volume ratio of a step, J = det(I + dt L), of the velocity gradients L (gdim, gdim, n),
 * component-first, as gradient writes them; gdim 2 or 3. */
void volume_ratio(int64_t n, int32_t gdim, const double *restrict L, double dt, double *restrict J)
{
#define F(a, b) ((a) == (b) ? 1.0 + dt * L[((a) * gdim + (b)) * n + k] : dt * L[((a) * gdim + (b)) * n + k])
  if (gdim == 2)
    for (int64_t k = 0; k < n; ++k)
      J[k] = F(0, 0) * F(1, 1) - F(0, 1) * F(1, 0);
  else
    for (int64_t k = 0; k < n; ++k)
      J[k] = F(0, 0) * (F(1, 1) * F(2, 2) - F(1, 2) * F(2, 1)) - F(0, 1) * (F(1, 0) * F(2, 2) - F(1, 2) * F(2, 0)) +
             F(0, 2) * (F(1, 0) * F(2, 1) - F(1, 1) * F(2, 0));
#undef F
}

void g2p(int64_t n, int32_t gdim, const int32_t *dofs, const double *N, const double *v_node, const double *a_node,
         const double *v_p, double dt, double flip, int32_t musl, const double *mass, double *v, double *dx,
         double *momenta)
{
  if (gdim == 2)
    g2p_of(n, 2, dofs, N, v_node, a_node, v_p, dt, flip, musl, mass, v, dx, momenta);
  else
    g2p_of(n, 3, dofs, N, v_node, a_node, v_p, dt, flip, musl, mass, v, dx, momenta);
}

void p2g(int64_t n, int32_t gdim, const int32_t *dofs, const double *N, const int32_t *cells, const double *grad,
         const double *m, const double *v_p, const double *sigma, const double *volume, double *mass,
         double *momentum, double *force)
{
  if (gdim == 2)
    p2g_of(n, 2, dofs, N, cells, grad, m, v_p, sigma, volume, mass, momentum, force);
  else
    p2g_of(n, 3, dofs, N, cells, grad, m, v_p, sigma, volume, mass, momentum, force);
}

/* The nodal volumetric average of volumetric.py, for velocity gradients L component-first
 * (gdim, gdim, n). volumetric_sums: tr[p] = sum_i L[i, i, p], vtr[p] = volume[p] tr[p] and
 * out[dofs[a, p]] += N[a, p] vtr[p] (out holds the sums on entry). volumetric_correct:
 * L[i, i, p] += (sum_a N[a, p] tr_node[dofs[a, p]] - tr[p]) / gdim. */
void volumetric_sums(int64_t n, int32_t gdim, const int32_t *dofs, const double *N, const double *L,
                     const double *volume, double *tr, double *vtr, double *out)
{
  for (int64_t p = 0; p < n; ++p)
  {
    double t = 0.0;
    for (int32_t i = 0; i < gdim; ++i)
      t += L[(i * gdim + i) * n + p];
    tr[p] = t;
    vtr[p] = volume[p] * t;
  }
  scatter(n, gdim + 1, dofs, N, 1, vtr, out);
}

void volumetric_correct(int64_t n, int32_t gdim, const int32_t *dofs, const double *N, const double *tr_node,
                        const double *tr, double *L)
{
  const int32_t nn = gdim + 1;
  for (int64_t p = 0; p < n; ++p)
  {
    double sum = 0.0;
    for (int32_t a = 0; a < nn; ++a)
      sum += N[a * n + p] * tr_node[dofs[a * n + p]];
    const double delta = (sum - tr[p]) / gdim;
    for (int32_t i = 0; i < gdim; ++i)
      L[(i * gdim + i) * n + p] += delta;
  }
}
