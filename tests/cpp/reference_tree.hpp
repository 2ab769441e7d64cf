// The reference for layerpilot's attribute octree, built from OctoMap itself: OctoMap's
// OccupancyOcTreeBase with a node that holds layerpilot's attributes (color, last seen, min
// distance) and counts them in node equality, so OctoMap prunes only voxels equal in every field,
// as ColorOcTree does with its color. Its `.ot` record is layerpilot's (tree id LayerpilotVoxelTree),
// so OctoMap's own reader and writer handle layerpilot's files.
#pragma once

#include <octomap/OccupancyOcTreeBase.h>
#include <octomap/OcTree.h>
#include <octomap/OcTreeNode.h>

#include <random>

#include "octomap_compare.hpp"

namespace layerpilot::test {

class VoxelNode : public octomap::OcTreeNode {
 public:
  Attributes attributes;

  bool operator==(const VoxelNode& o) const { return value == o.value && attributes == o.attributes; }
  void copyData(const VoxelNode& from) {
    value = from.value;
    attributes = from.attributes;
  }
  std::istream& readData(std::istream& s);
  std::ostream& writeData(std::ostream& s) const;
};

class VoxelTree : public octomap::OccupancyOcTreeBase<VoxelNode> {
 public:
  explicit VoxelTree(double resolution);
  VoxelTree* create() const override { return new VoxelTree(resolution); }
  std::string getTreeType() const override { return "LayerpilotVoxelTree"; }

  // OctoMap's discretized insertPointCloud (computeDiscreteUpdate, free then occupied cells,
  // OctoMap's updateNode), then layerpilot's attribute rules on every hit voxel (also one already
  // at the upper clamping bound): the mean color of the frame's points in it, `stamp`, the nearest
  // point's distance.
  // Inner nodes and pruning are done once at the end (updateInnerOccupancy, prune).
  void insert(const Cloud& cloud, const Colors& colors, const octomap::point3d& origin, float stamp,
              double max_range);

 private:
  struct Registration {  // OctoMap's factory pattern (as ColorOcTree's StaticMemberInitializer)
    Registration();
    void ensureLinking() {}
  };
  static Registration registration;
};

inline Attributes attributesOfNode(const VoxelNode& n) { return n.attributes; }

// layerpilot's map, OctoMap's OcTree and the attribute reference side by side: each frame goes into
// all three, with colors and a time.
struct SideBySide {
  VoxelMap ours;
  octomap::OcTree stock;
  VoxelTree reference;
  explicit SideBySide(double resolution) : ours(resolution, SensorModel{}), stock(resolution), reference(resolution) {}

  void insert(const Cloud& c, std::mt19937& rng, const octomap::point3d& origin, float stamp, double max_range) {
    Colors colors(c.points.rows(), 3);
    std::uniform_int_distribution<int> byte(0, 3);  // few colors: neighbours are often equal, so they prune
    for (Eigen::Index i = 0; i < colors.size(); ++i) colors.data()[i] = static_cast<uint8_t>(80 * byte(rng));
    ours.insert(c.points, colors, Eigen::Vector3d(origin.x(), origin.y(), origin.z()), stamp, max_range);
    stock.insertPointCloud(c.octomap, origin, max_range, false, true);
    reference.insert(c, colors, origin, stamp, max_range);
  }

  // Every voxel's log-odds as OctoMap's OcTree; every node as the attribute reference.
  ::testing::AssertionResult same() const {
    const auto nodes = nodesOf(ours);
    auto voxels = sameVoxels(voxelsOf(nodes), voxelsOf(nodesOf(stock)));
    if (!voxels) return voxels << " (against OctoMap's OcTree)";
    auto tree = sameNodes(nodes, nodesOf(reference));
    if (!tree) return tree << " (against OctoMap with layerpilot's node)";
    return ::testing::AssertionSuccess();
  }
};

}  // namespace layerpilot::test
