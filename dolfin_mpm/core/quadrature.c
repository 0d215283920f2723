/* The cell quadrature's weights (quadrature.py), in two passes around the assembly over ranks.
 * dofs, N: (nn, n) point-major per node of the cell; cell_dofs: (nn, num_cells). */
#include <stdint.h>

/* Local sums, into zeroed arrays: each cell's volume of points (total, num_cells) and each
 * node's share of the owned cells that hold points (patch). */
void quadrature_sums(int64_t n, const int64_t *restrict cells, const double *restrict volume, int64_t num_cells,
                     int64_t num_owned, int32_t nn, const int32_t *restrict cell_dofs,
                     const double *restrict cell_volume, double *restrict total, double *restrict patch)
{
  for (int64_t p = 0; p < n; ++p)
    total[cells[p]] += volume[p];
  for (int64_t e = 0; e < num_owned; ++e)
    if (total[e] > 0.0)
      for (int32_t a = 0; a < nn; ++a)
        patch[cell_dofs[a * num_cells + e]] += cell_volume[e] / nn;
}

/* Each point's factor: A_e / total_e where every node of its cell has sums / patch >= full. */
void quadrature_weights(int64_t n, int32_t nn, const int32_t *restrict dofs,
                        const int64_t *restrict cells, const double *restrict sums,
                        const double *restrict patch, const double *restrict total,
                        const double *restrict cell_volume, double full, double *restrict w)
{
  for (int64_t p = 0; p < n; ++p)
  {
    int inside = 1;
    for (int32_t a = 0; a < nn; ++a)
    {
      const int32_t i = dofs[a * n + p];
      inside &= patch[i] > 0.0 && sums[i] >= full * patch[i];
    }
    const int64_t c = cells[p];
    w[p] = inside ? cell_volume[c] / total[c] : 1.0;
  }
}
