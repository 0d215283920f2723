/* The volume-weighted mean stress of each particle's (cell, material) group.
 * sigma and out are component-first (9, n), symmetric (the upper triangle is read); the group of
 * particle p is key[p] = cell[p] groups + material[p]; w[p] is its weight (0: the point keeps
 * its stress and is out of the means); total (num_cells groups) and sums (6 of each) are
 * zeroed scratch. A run of particles of one group (they come in runs where they are ordered
 * by cell) sums in registers: the sums and their order are those of one term at a time. Each
 * group's sums become its mean with one division a component, before the pass that writes them.
 * out may be sigma itself; then a component that is zero at every point (the out-of-plane shears
 * of plane strain) is left as it is, its means being zero too. */
#include <stdint.h>
#include <string.h>

typedef double v2 __attribute__((vector_size(16)));
typedef double v4 __attribute__((vector_size(32)));

static const int UPPER[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};

static inline int64_t group_of(int64_t p, int32_t groups, const int32_t *cell, const int32_t *material)
{
  return (int64_t)cell[p] * groups + (groups > 1 ? material[p] : 0);
}

void cell_mean(int64_t n, int64_t num_cells, int32_t groups, const int32_t *restrict cell,
               const int32_t *restrict material, const double *restrict w, const double *sigma, double *out,
               double *restrict total, double *restrict sums)
{
  const double *S[6];
  for (int c = 0; c < 6; ++c)
    S[c] = sigma + (3 * UPPER[c][0] + UPPER[c][1]) * n;
  int64_t p = 0;
  int nonzero[6] = {0, 0, 0, 0, 0, 0}; /* whether any point has the component */
  while (p < n)
  {
    const int64_t k = group_of(p, groups, cell, material);
    double t = total[k], s[6];
    for (int c = 0; c < 6; ++c)
      s[c] = sums[6 * k + c];
    for (; p < n && group_of(p, groups, cell, material) == k; ++p)
    {
      t += w[p];
      for (int c = 0; c < 6; ++c)
      {
        s[c] += w[p] * S[c][p];
        nonzero[c] |= S[c][p] != 0.0;
      }
    }
    total[k] = t;
    for (int c = 0; c < 6; ++c)
      sums[6 * k + c] = s[c];
  }
  const int64_t size = num_cells * groups;
  for (int64_t k = 0; k < size; ++k) /* each group's mean, one division a component */
  {
    const double t = total[k] > 0.0 ? total[k] : 1.0; /* no particle weighs in: sums of 0 */
    v4 m4;
    v2 m2;
    memcpy(&m4, sums + 6 * k, sizeof m4);
    memcpy(&m2, sums + 6 * k + 4, sizeof m2);
    m4 /= t; /* four components and two a division (the compiler leaves the scalar loop scalar) */
    m2 /= t;
    memcpy(sums + 6 * k, &m4, sizeof m4);
    memcpy(sums + 6 * k + 4, &m2, sizeof m2);
  }
  /* Written a block of particles at a time and, in a block, a component at a time: two output
   * streams at once, not nine (nine are twice as slow where the particles are not in cell order
   * and n is a multiple of 512, every stream then in the same cache sets). */
  enum { BLOCK = 64 };
  int64_t at[BLOCK];
  for (int64_t q0 = 0; q0 < n; q0 += BLOCK)
  {
    const int64_t m = n - q0 < BLOCK ? n - q0 : BLOCK;
    for (int64_t q = 0; q < m; ++q) /* where each particle's mean is, -1: its own stress */
      at[q] = w[q0 + q] > 0.0 ? 6 * group_of(q0 + q, groups, cell, material) : -1;
    for (int c = 0; c < 6; ++c)
    {
      if (!nonzero[c] && out == sigma) /* zero at every point, and so its means: already written */
        continue;
      const int a = UPPER[c][0], b = UPPER[c][1];
      double *lower = out + (3 * b + a) * n + q0, *upper = out + (3 * a + b) * n + q0;
      const double *own = S[c] + q0; /* the upper triangle: read before it is written, when out is sigma */
      for (int64_t q = 0; q < m; ++q)
      {
        const double mean = at[q] >= 0 ? sums[at[q] + c] : own[q];
        upper[q] = mean;
        lower[q] = mean;
      }
    }
  }
}
