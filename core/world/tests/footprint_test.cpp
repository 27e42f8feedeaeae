// Footprints: hull, intersection, distance, and the grid broad phase against the naive check.
#include "cell/world/footprint.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <set>

#include "cell/testing/tolerances.hpp"

namespace cell::world {
namespace {

using ::cell::testing::kTolMm;

Footprint square(double x, double y, double side, double yaw = 0.0) {
  const double h = side / 2.0;
  return place_footprint({{-h, -h}, {h, -h}, {h, h}, {-h, h}}, x, y, yaw);
}

TEST(ConvexHull, DropsInteriorAndCollinearPointsCounterClockwise) {
  const auto hull = convex_hull({{0, 0}, {2, 0}, {1, 0}, {2, 2}, {0, 2}, {1, 1}, {0, 2}});
  ASSERT_EQ(hull.size(), 4U);
  double area = 0.0;
  for (std::size_t i = 0; i < hull.size(); ++i) {
    const auto& u = hull[i];
    const auto& v = hull[(i + 1) % hull.size()];
    area += u.x() * v.y() - v.x() * u.y();
  }
  EXPECT_NEAR(area / 2.0, 4.0, kTolMm);
}

TEST(Footprint, DistanceAndIntersection) {
  const Footprint a = square(0, 0, 2);
  EXPECT_TRUE(intersects(a, square(1.5, 0, 2)));
  EXPECT_TRUE(intersects(a, square(2.0, 0, 2)));  // touching edges share points
  EXPECT_FALSE(intersects(a, square(3.0, 0, 2)));
  EXPECT_NEAR(distance(a, square(5, 0, 2)), 3.0, kTolMm);
  EXPECT_NEAR(distance(a, square(4, 4, 2)), std::sqrt(8.0), kTolMm);  // corner to corner
  EXPECT_DOUBLE_EQ(distance(a, square(0.5, 0.5, 2)), 0.0);
  // A diamond whose tip points at the square: separated along the diagonal only.
  const Footprint diamond = square(1.0 + std::sqrt(2.0) + 0.5, 0, 2, std::numbers::pi / 4);
  EXPECT_FALSE(intersects(a, diamond));
  EXPECT_NEAR(distance(a, diamond), 0.5, 1e-9);
  // One inside the other.
  EXPECT_TRUE(intersects(square(0, 0, 10), square(1, 1, 1)));
}

TEST(Footprint, TooCloseHonoursTheSeparation) {
  const Footprint a = square(0, 0, 2);
  const Footprint b = square(5, 0, 2);  // 3 mm apart
  EXPECT_FALSE(too_close(a, b, 0.0));
  EXPECT_FALSE(too_close(a, b, 3.0));
  EXPECT_TRUE(too_close(a, b, 3.01));
  EXPECT_TRUE(too_close(a, square(1, 0, 2), 0.0));
}

TEST(Footprint, ContainsAndTranslate) {
  Footprint f = square(0, 0, 2, 0.3);
  EXPECT_TRUE(contains(f, {0.5, 0.5}));
  EXPECT_FALSE(contains(f, {2, 2}));
  f.translate({10, 0});
  EXPECT_TRUE(contains(f, {10.5, 0.5}));
  EXPECT_NEAR(f.min.x(), square(10, 0, 2, 0.3).min.x(), kTolMm);
}

TEST(Footprint, ProjectingAnUprightPartEqualsPlacingIt) {
  const std::vector<Eigen::Vector2d> outline = {{-5, -2}, {5, -2}, {5, 2}, {-5, 2}};
  std::vector<Eigen::Vector3d> hull;
  for (const auto& p : outline) {
    hull.emplace_back(p.x(), p.y(), 0.0);
    hull.emplace_back(p.x(), p.y(), 3.0);
  }
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(12, -4, 750);
  const Footprint a = project_footprint(hull, pose);
  const Footprint b = place_footprint(outline, 12, -4, 0.7);
  EXPECT_TRUE(a.min.isApprox(b.min));
  EXPECT_TRUE(a.max.isApprox(b.max));
  EXPECT_NEAR(distance(a, b), 0.0, kTolMm);
}

// The grid's candidates are a superset of the footprints the naive check finds too close.
TEST(FootprintGrid, FindsEveryConflictTheNaiveCheckFinds) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> pos(0.0, 500.0);
  std::uniform_real_distribution<double> yaw(-3.0, 3.0);
  std::vector<Footprint> all;
  all.reserve(400);
  for (int i = 0; i < 400; ++i) {
    all.push_back(
        place_footprint({{-15, -4}, {15, -4}, {15, 4}, {-15, 4}}, pos(rng), pos(rng), yaw(rng)));
  }
  constexpr double kSep = 6.0;
  FootprintGrid grid(40.0);
  for (std::size_t i = 0; i < all.size(); ++i) {
    grid.insert(i, all[i]);
  }
  int conflicts = 0;
  for (std::size_t q = 0; q < all.size(); ++q) {
    std::set<std::size_t> candidates;
    grid.for_each_candidate(all[q], kSep, [&](std::size_t i) {
      EXPECT_TRUE(candidates.insert(i).second) << "candidate reported twice";
    });
    for (std::size_t i = 0; i < all.size(); ++i) {
      if (i != q && too_close(all[q], all[i], kSep)) {
        ++conflicts;
        EXPECT_TRUE(candidates.contains(i)) << q << " vs " << i;
      }
    }
  }
  EXPECT_GT(conflicts, 0);  // the test exercised real conflicts
}

TEST(FootprintGrid, HugeFootprintsAreStillFound) {
  FootprintGrid grid(10.0);
  grid.insert(0, square(0, 0, 5000));  // spans far more cells than the grid indexes
  grid.insert(1, square(3000, 3000, 2));
  std::set<std::size_t> found;
  grid.for_each_candidate(square(100, 100, 2), 0.0, [&](std::size_t i) { found.insert(i); });
  EXPECT_TRUE(found.contains(0));
  EXPECT_FALSE(found.contains(1));
  found.clear();
  grid.for_each_candidate(square(0, 0, 100000), 0.0, [&](std::size_t i) { found.insert(i); });
  EXPECT_EQ(found.size(), 2U);
}

}  // namespace
}  // namespace cell::world
