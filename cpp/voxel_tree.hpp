// The `.ot` file type of the map: OctoMap's occupancy node plus the voxel attributes, following
// OctoMap's custom-node pattern (as ColorOcTree does) and registered as `LayerpilotVoxelTree`.
// The map itself lives in a CompactOctree; this OctoMap tree only reads files.
#pragma once

#include <octomap/OccupancyOcTreeBase.h>
#include <octomap/OcTreeNode.h>

#include <cmath>
#include <cstdint>
#include <istream>
#include <limits>
#include <ostream>

#include "compact_octree.hpp"

namespace layerpilot {

class VoxelNode : public octomap::OcTreeNode {
 public:
  friend class VoxelTree;

  VoxelNode() = default;
  VoxelNode(const VoxelNode& rhs)
      : OcTreeNode(rhs), color(rhs.color), last_seen(rhs.last_seen), min_distance(rhs.min_distance) {}

  // Pruning compares every attribute, so a voxel never loses its own color/time/distance.
  bool operator==(const VoxelNode& rhs) const {
    return rhs.value == value && rhs.color == color && sameFloat(rhs.last_seen, last_seen) &&
           rhs.min_distance == min_distance;
  }

  void copyData(const VoxelNode& from) {
    OcTreeNode::copyData(from);
    color = from.color;
    last_seen = from.last_seen;
    min_distance = from.min_distance;
  }

  std::istream& readData(std::istream& s) {
    s.read(reinterpret_cast<char*>(&value), sizeof(value));
    s.read(reinterpret_cast<char*>(&color), sizeof(color));
    s.read(reinterpret_cast<char*>(&last_seen), sizeof(last_seen));
    s.read(reinterpret_cast<char*>(&min_distance), sizeof(min_distance));
    return s;
  }

  std::ostream& writeData(std::ostream& s) const {
    s.write(reinterpret_cast<const char*>(&value), sizeof(value));
    s.write(reinterpret_cast<const char*>(&color), sizeof(color));
    s.write(reinterpret_cast<const char*>(&last_seen), sizeof(last_seen));
    s.write(reinterpret_cast<const char*>(&min_distance), sizeof(min_distance));
    return s;
  }

  bool observed() const { return !std::isnan(last_seen); }

  Rgb color;
  // Mission clock seconds (float32: ~1 ms resolution over a 2-hour mission); NaN = never hit.
  float last_seen = std::numeric_limits<float>::quiet_NaN();
  // Metres from the sensor origin, minimum over all hits; +inf = never hit.
  float min_distance = std::numeric_limits<float>::infinity();

 private:
  static bool sameFloat(float a, float b) { return a == b || (std::isnan(a) && std::isnan(b)); }
};

class VoxelTree : public octomap::OccupancyOcTreeBase<VoxelNode> {
 public:
  explicit VoxelTree(double resolution);
  VoxelTree* create() const override { return new VoxelTree(resolution); }
  std::string getTreeType() const override { return "LayerpilotVoxelTree"; }

 private:
  // Registers the type with OctoMap's factory once, so AbstractOcTree::read can create it.
  struct StaticMemberInitializer {
    StaticMemberInitializer();
    void ensureLinking() {}
  };
  static StaticMemberInitializer registration_;
};

}  // namespace layerpilot
