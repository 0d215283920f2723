/* The per-particle loops of locate.py, one pass over the particles each.
 *
 * Cells are affine simplices of gdim + 1 nodes: x = x0 + J xi, K = J^-1, stored
 * component-first over the cells (locate.Grid: x0_T (gdim, cells), K (gdim, gdim, cells),
 * cell nodes (gdim + 1, cells)); particle positions
 * are (n, 3) row-major, the outputs component-first (particle axis last). Each loop is compiled
 * for 2D and 3D with the dimension a constant.
 */
#include <stdint.h>

#define INLINE static inline __attribute__((always_inline))

/* lam[:, p] = barycentric coordinates of x[p] in cells[p]; inside[p] = 1 when cells[p] >= 0 and
 * every coordinate is >= -tol. A negative cell is read as cell 0 (its coordinates are not used). */
INLINE void barycentric_of(int64_t n, int32_t gdim, const double *restrict x, const int32_t *restrict cells,
                           int64_t num_cells, const double *restrict x0, const double *restrict K, double tol,
                           double *restrict lam, int8_t *restrict inside)
{
  for (int64_t p = 0; p < n; ++p)
  {
    const int64_t c = cells[p] >= 0 ? cells[p] : 0;
    double dx[3];
    for (int32_t j = 0; j < gdim; ++j)
      dx[j] = x[3 * p + j] - x0[j * num_cells + c];
    double sum = 0.0, least;
    for (int32_t i = 0; i < gdim; ++i)
    {
      double l = K[(i * gdim) * num_cells + c] * dx[0];
      for (int32_t j = 1; j < gdim; ++j)
        l += K[(i * gdim + j) * num_cells + c] * dx[j];
      lam[(i + 1) * n + p] = l;
      sum = i == 0 ? l : sum + l;
      least = i == 0 ? l : (l < least ? l : least);
    }
    lam[p] = 1.0 - sum;
    least = lam[p] < least ? lam[p] : least;
    inside[p] = cells[p] >= 0 && least >= -tol;
  }
}

/* dofs[a, p] = nodes[a, cells[p]]. */
INLINE void gather_of(int64_t n, int32_t gdim, const int32_t *restrict cells, int64_t num_cells,
                      const int32_t *restrict nodes, int32_t *restrict dofs)
{
  for (int32_t a = 0; a <= gdim; ++a)
    for (int64_t p = 0; p < n; ++p)
      dofs[a * n + p] = nodes[a * num_cells + cells[p]];
}

void barycentric(int64_t n, int32_t gdim, const double *x, const int32_t *cells, int64_t num_cells,
                 const double *x0, const double *K, double tol, double *lam, int8_t *inside)
{
  if (gdim == 2)
    barycentric_of(n, 2, x, cells, num_cells, x0, K, tol, lam, inside);
  else
    barycentric_of(n, 3, x, cells, num_cells, x0, K, tol, lam, inside);
}

void gather_nodes(int64_t n, int32_t gdim, const int32_t *cells, int64_t num_cells, const int32_t *nodes,
                  int32_t *dofs)
{
  if (gdim == 2)
    gather_of(n, 2, cells, num_cells, nodes, dofs);
  else
    gather_of(n, 3, cells, num_cells, nodes, dofs);
}
