// Tests of the spatial hash: box queries equal a brute-force scan, before and after atoms move,
// on both the cell walk and the scan-all path; far and non-finite positions are filed safely.
#include "idms/sim/spatial_hash.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "alloc_counter.h"

namespace idms {
namespace {

std::vector<int32_t> Query(const SpatialHash& h, const double lo[3], const double hi[3]) {
  std::vector<int32_t> out;
  ForEachAtomInBox(h, lo, hi, [&](int32_t a) { out.push_back(a); });
  std::sort(out.begin(), out.end());
  return out;
}

// Atoms inside the box (the hash may return more: whole cells; never fewer).
std::vector<int32_t> Inside(const std::vector<Real>& pos, const double lo[3], const double hi[3]) {
  std::vector<int32_t> out;
  for (int32_t a = 0; a < static_cast<int32_t>(pos.size() / 3); ++a) {
    bool in = true;
    for (int c = 0; c < 3; ++c) in = in && pos[3 * a + c] >= lo[c] && pos[3 * a + c] <= hi[c];
    if (in) out.push_back(a);
  }
  return out;
}

void ExpectSupersetWithoutDuplicates(const std::vector<int32_t>& got, const std::vector<int32_t>& inside) {
  EXPECT_TRUE(std::adjacent_find(got.begin(), got.end()) == got.end()) << "duplicate atom";
  EXPECT_TRUE(std::includes(got.begin(), got.end(), inside.begin(), inside.end())) << "missed an atom";
}

TEST(SpatialHash, BoxQueriesCoverEveryAtomInsideOnceBeforeAndAfterMoves) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-20, 20);
  const int32_t n = 5000;
  std::vector<Real> pos(3 * n);
  for (Real& x : pos) x = u(rng);
  SpatialHash h;
  BuildSpatialHash(1.7, pos.data(), n, &h);
  for (int round = 0; round < 3; ++round) {
    for (int q = 0; q < 50; ++q) {
      double lo[3], hi[3];
      for (int c = 0; c < 3; ++c) {
        const double a = u(rng), w = std::fabs(u(rng)) / 4;
        lo[c] = a - w, hi[c] = a + w;
      }
      const std::vector<int32_t> got = Query(h, lo, hi), inside = Inside(pos, lo, hi);
      ExpectSupersetWithoutDuplicates(got, inside);
      // Only atoms of the touched cells come back: nothing farther than one cell from the box.
      for (int32_t a : got) {
        for (int c = 0; c < 3; ++c) {
          EXPECT_GE(pos[3 * a + c], lo[c] - h.cell);
          EXPECT_LE(pos[3 * a + c], hi[c] + h.cell);
        }
      }
    }
    // Move a third of the atoms (some far), refile them, and query again, without allocating.
    const int64_t before = test::AllocationCount();
    for (int32_t a = 0; a < n; a += 3) {
      for (int c = 0; c < 3; ++c) pos[3 * a + c] += u(rng) / 5;
      UpdateSpatialHash(h, a, &pos[3 * a]);
    }
    EXPECT_EQ(test::AllocationCount() - before, 0);
  }
}

TEST(SpatialHash, HugeBoxScansEverythingWithTheSameResult) {
  std::vector<Real> pos = {0, 0, 0, 100, 100, 100, -50, 3, 7, 1e6, 0, 0};
  SpatialHash h;
  BuildSpatialHash(0.01, pos.data(), 4, &h);
  const double lo[3] = {-1e3, -1e3, -1e3}, hi[3] = {1e3, 1e3, 1e3};  // ~10^15 cells: scan path
  EXPECT_EQ(Query(h, lo, hi), (std::vector<int32_t>{0, 1, 2}));
  const double lo2[3] = {99, 99, 99}, hi2[3] = {101, 101, 101};  // cell walk
  EXPECT_EQ(Query(h, lo2, hi2), (std::vector<int32_t>{1}));
}

TEST(SpatialHash, NonFiniteAndFarPositionsAreFiledWithoutHarm) {
  const Real nan = std::numeric_limits<Real>::quiet_NaN(), inf = std::numeric_limits<Real>::infinity();
  std::vector<Real> pos = {nan, 0, 0, inf, -inf, 0, 1e300, 0, 0, 0.5, 0.5, 0.5};
  SpatialHash h;
  BuildSpatialHash(1.0, pos.data(), 4, &h);
  const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
  EXPECT_EQ(Query(h, lo, hi), (std::vector<int32_t>{3}));
  // Moving the NaN atom back to a finite place makes it findable again.
  pos[0] = 0.25;
  UpdateSpatialHash(h, 0, &pos[0]);
  EXPECT_EQ(Query(h, lo, hi), (std::vector<int32_t>{0, 3}));
}

TEST(SpatialHash, EmptyBoxAndInvertedBoxFindNothing) {
  std::vector<Real> pos = {0, 0, 0};
  SpatialHash h;
  BuildSpatialHash(1.0, pos.data(), 1, &h);
  const double lo[3] = {5, 5, 5}, hi[3] = {6, 6, 6}, inv_lo[3] = {1, 1, 1}, inv_hi[3] = {-1, -1, -1};
  EXPECT_TRUE(Query(h, lo, hi).empty());
  EXPECT_TRUE(Query(h, inv_lo, inv_hi).empty());
}

}  // namespace
}  // namespace idms
