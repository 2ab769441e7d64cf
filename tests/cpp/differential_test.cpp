// layerpilot's compact octree against OctoMap: the same clouds give every voxel the log-odds of
// OctoMap's own OcTree, bit for bit; the same tree, node for node (structure, pruning, log-odds,
// attributes), as OctoMap's OccupancyOcTreeBase with layerpilot's node (reference_tree.hpp); and
// the same castRay answers.
#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <random>

#include "reference_tree.hpp"

namespace layerpilot::test {
namespace {

// OctoMap's discretized insertion (what VoxelMap::insert implements); lazy_eval off, as OctoMap's default.
void insertBoth(VoxelMap& ours, octomap::OcTree& ref, const Cloud& c, const octomap::point3d& origin,
                double max_range) {
  ours.insert(c.points, noColors(), Eigen::Vector3d(origin.x(), origin.y(), origin.z()), 0.0, max_range);
  ref.insertPointCloud(c.octomap, origin, max_range, false, true);
}

struct RandomCase {
  double resolution;
  unsigned seed;
  double max_range;  // < 0: unlimited
};

class RandomClouds : public ::testing::TestWithParam<RandomCase> {};

TEST_P(RandomClouds, EveryNodeEqualsOctoMapsAfterEveryFrame) {
  const auto [resolution, seed, max_range] = GetParam();
  const float far = static_cast<float>(40 * resolution);
  SideBySide maps(resolution);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> near(-0.1f * far, 0.1f * far);
  for (int frame = 0; frame < 8; ++frame) {
    const octomap::point3d origin(near(rng), near(rng), near(rng));
    maps.insert(makeCloud(randomFrame(rng, 3000, far)), rng, origin, 0.5f * frame, max_range);
    ASSERT_TRUE(maps.same()) << "after frame " << frame;
  }
  const auto nodes = nodesOf(maps.ours);
  EXPECT_GT(nodes.size(), 20000u);
  EXPECT_GT(leavesAbove(nodes, 16), 100u) << "the scene must exercise pruning";
  EXPECT_EQ(maps.ours.stats().nodes, maps.reference.size());
}

INSTANTIATE_TEST_SUITE_P(Octomap, RandomClouds,
                         ::testing::Values(RandomCase{1.0, 1, 30.0}, RandomCase{0.2, 2, 6.0},
                                           RandomCase{0.05, 3, -1.0}, RandomCase{0.37, 4, 100.0}),
                         [](const ::testing::TestParamInfo<RandomCase>& info) {
                           const RandomCase& c = info.param;
                           return "res_" + std::to_string(int(c.resolution * 100)) + "cm_range_" +
                                  (c.max_range < 0 ? std::string("unlimited") : std::to_string(int(c.max_range)) + "m");
                         });

// The real scan (88,206 points from one origin) at 0.2 m and 1 m.
TEST(RealScan, EveryNodeEqualsOctoMaps) {
  const Cloud scan = makeCloud(scanPoints());
  ASSERT_EQ(scan.octomap.size(), 88206u);
  for (const double resolution : {0.2, 1.0}) {
    SideBySide maps(resolution);
    std::mt19937 rng(5);
    maps.insert(scan, rng, octomap::point3d(0, 0, 0), 1.f, -1.0);
    EXPECT_TRUE(maps.same()) << "at " << resolution << " m";
    EXPECT_GT(maps.stock.size(), resolution < 0.5 ? 40000u : 2000u);
  }
}

// A frame inserted twice: OctoMap updates each voxel once per frame, a hit winning over a miss.
TEST(Insertion, RepeatedFramesClampAndPruneAsOctoMap) {
  SideBySide maps(0.5);
  std::mt19937 rng(7);
  const Cloud wall = makeCloud(randomFrame(rng, 2000, 10.f));
  for (int i = 0; i < 8; ++i) {
    maps.insert(wall, rng, octomap::point3d(0.1f, -0.2f, 0.3f), float(i), 12.0);
    ASSERT_TRUE(maps.same()) << "after frame " << i;
  }
  size_t clamped_max = 0, clamped_min = 0;
  for (const auto& n : nodesOf(maps.ours)) {
    clamped_max += !n.inner && n.log_odds == maps.stock.getClampingThresMaxLog();
    clamped_min += !n.inner && n.log_odds == maps.stock.getClampingThresMinLog();
  }
  EXPECT_GT(clamped_max, 100u);
  EXPECT_GT(clamped_min, 100u);
  size_t hit = 0;  // every voxel hit was hit in each frame: all were last seen in the last one,
  for (const auto& n : nodesOf(maps.ours))  // those at the upper bound included
    if (!n.inner && std::isfinite(n.attributes.last_seen)) {
      ++hit;
      EXPECT_EQ(n.attributes.last_seen, 7.f) << describe(n);
    }
  EXPECT_GT(hit, 100u);
}

// castRay (unknown cells ignored, as VoxelMap::raycast) from random origins in random directions.
TEST(Raycast, AnswersAsOctoMapsCastRay) {
  VoxelMap ours(0.5, SensorModel{});
  octomap::OcTree ref(0.5);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (int frame = 0; frame < 4; ++frame)
    insertBoth(ours, ref, makeCloud(randomFrame(rng, 3000, 20.f)), octomap::point3d(u(rng), u(rng), u(rng)), 25.0);
  size_t hits = 0, misses = 0;
  for (int i = 0; i < 3000; ++i) {
    const octomap::point3d origin(8 * u(rng), 8 * u(rng), 4 * u(rng));
    octomap::point3d direction(u(rng), u(rng), u(rng));
    if (i % 10 == 0) direction = octomap::point3d(u(rng) > 0 ? 1.f : -1.f, 0.f, 0.f);  // along an axis
    const double max_range = i % 3 == 0 ? 5.0 : 40.0;
    octomap::point3d end;
    const bool ref_hit = ref.castRay(origin, direction, end, true, max_range);
    const auto hit = ours.raycast(Eigen::Vector3d(origin.x(), origin.y(), origin.z()),
                                  Eigen::Vector3d(direction.x(), direction.y(), direction.z()), max_range);
    ASSERT_EQ(hit.has_value(), ref_hit) << "ray " << i;
    if (!ref_hit) {
      ++misses;
      continue;
    }
    ++hits;
    EXPECT_EQ(hit->x(), end.x()) << "ray " << i;
    EXPECT_EQ(hit->y(), end.y()) << "ray " << i;
    EXPECT_EQ(hit->z(), end.z()) << "ray " << i;
  }
  EXPECT_GT(hits, 500u);
  EXPECT_GT(misses, 500u);
}

// "Occupied" is OctoMap's isNodeOccupied (log-odds >= the threshold's) everywhere: a voxel
// exactly at the threshold is occupied for the column layers, raycast, .bt, stats and voxels().
TEST(Occupied, AtTheThresholdIsOccupiedEverywhereAsInOctoMap) {
  SensorModel model;
  model.occupied_threshold = model.prob_hit;  // one hit from 0 lands exactly on the threshold
  VoxelMap ours(1.0, model);
  octomap::OcTree ref(1.0);
  ref.setOccupancyThres(model.occupied_threshold);
  const Cloud one = makeCloud({octomap::point3d(5.5f, 0.5f, 0.5f)});
  insertBoth(ours, ref, one, octomap::point3d(0.5f, 0.5f, 0.5f), -1.0);
  const octomap::OcTreeNode* voxel = ref.search(5.5, 0.5, 0.5);
  ASSERT_NE(voxel, nullptr);
  ASSERT_EQ(voxel->getLogOdds(), ref.getOccupancyThresLog());
  ASSERT_TRUE(ref.isNodeOccupied(voxel));
  ASSERT_TRUE(sameVoxels(voxelsOf(nodesOf(ours)), voxelsOf(nodesOf(ref))));

  EXPECT_EQ(ours.stats().occupied_leaves, 1u);
  const ColumnWindow w = ours.columnLayers(32768 + 5, 32768, 1, 1);
  EXPECT_EQ(w.observed[0], 1);
  const auto hit = ours.raycast(Eigen::Vector3d(0.5, 0.5, 0.5), Eigen::Vector3d(1, 0, 0), 10.0);
  ASSERT_TRUE(hit.has_value());
  EXPECT_EQ(hit->x(), 5.5);
  EXPECT_EQ(ours.voxels(Eigen::Vector3d(-9, -9, -9), Eigen::Vector3d(9, 9, 9), model.occupied_threshold).size(), 1u);
  const std::string bt = ours.serialize(FileFormat::Bt);
  std::istringstream in(bt);
  octomap::OcTree back(1.0);
  ASSERT_TRUE(back.readBinary(in));
  const octomap::OcTreeNode* read = back.search(5.5, 0.5, 0.5);
  ASSERT_NE(read, nullptr);
  EXPECT_EQ(read->getLogOdds(), back.getClampingThresMaxLog()) << ".bt must mark it occupied";
}

}  // namespace
}  // namespace layerpilot::test
